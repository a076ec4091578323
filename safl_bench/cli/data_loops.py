"""`safl-bench data loops`: export the ground-truth loop pairs of any KITTI poses file.

Output: a CSV with the header line `query,match` and then one pair per line, 0-based frame
indices, sorted by query then match: every pair where frame `match` lies within --radius metres
of frame `query` in the ground plane (camera x, z of the KITTI poses) and is older than it by
more than --min-gap-s seconds (stamps from --times, or i * 0.1 s when it is absent, KITTI's
10 Hz). Compare it with other tools' ground truth.
"""

from __future__ import annotations

import argparse

import numpy as np

from safl_bench.common.atomic import atomic_write_text
from safl_bench.errors import ConfigError, DataError
from safl_bench.evaluation.groundtruth import (
    DEFAULT_PERIOD_S,
    camera_ground_positions,
    default_times,
    loop_pairs,
    read_poses,
    read_times,
)

HELP = "export the ground-truth loop pairs (query,match) of a KITTI poses file as CSV"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """--poses, --times, --radius, --min-gap-s, --out."""
    parser.add_argument(
        "--poses", required=True, metavar="FILE", help="KITTI poses file (12 numbers a line)"
    )
    parser.add_argument(
        "--times",
        metavar="FILE",
        help=f"KITTI times.txt (one stamp a line); default: frames {DEFAULT_PERIOD_S} s apart",
    )
    parser.add_argument(
        "--radius", required=True, type=float, metavar="R", help="max ground-plane distance (m)"
    )
    parser.add_argument(
        "--min-gap-s",
        required=True,
        type=float,
        metavar="S",
        help="the match must be older than the query by more than S seconds",
    )
    parser.add_argument(
        "--out", required=True, metavar="CSV", help="output CSV (header query,match)"
    )


def main(args: argparse.Namespace) -> int:
    """Write the pairs and print a one-line summary."""
    if not np.isfinite(args.radius) or args.radius < 0:
        raise ConfigError(f"--radius must be a finite distance >= 0 m, got {args.radius}")
    if not np.isfinite(args.min_gap_s) or args.min_gap_s < 0:
        raise ConfigError(
            f"--min-gap-s must be a finite number of seconds >= 0, got {args.min_gap_s}"
        )
    poses = read_poses(args.poses)
    n = len(poses)
    times = read_times(args.times, n) if args.times else default_times(n)
    pairs = loop_pairs(camera_ground_positions(poses), times, args.radius, args.min_gap_s)
    lines = ["query,match", *(f"{q},{m}" for q, m in pairs.tolist())]
    try:
        atomic_write_text(args.out, "\n".join(lines) + "\n")
    except OSError as exc:
        raise DataError(f"cannot write {args.out}: {exc.strerror or exc}") from None
    clock = (
        f"stamps from {args.times}" if args.times else f"frames assumed {DEFAULT_PERIOD_S} s apart"
    )
    queries = len(np.unique(pairs[:, 0]))
    print(
        f"{len(pairs)} loop pairs ({queries} of {n} frames revisit a place) within {args.radius:g} m "
        f"and older than {args.min_gap_s:g} s ({clock}) -> {args.out}"
    )
    return 0
