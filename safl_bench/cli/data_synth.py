"""`safl-bench data synth`: generate the embedded synthetic dataset in the KITTI odometry layout."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from safl_bench.cli.options import seed
from safl_bench.errors import DataError

HELP = "generate the synthetic town + simulated 64-beam LiDAR sequences (KITTI odometry layout)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `data synth`."""
    parser.add_argument("--out", metavar="DIR", default=None,
                        help="dataset root to write (default: the default root of the seed and "
                             "data version, $SAFL_HOME/synth/v6/seed-N; version 5: synth/seed-N)")
    parser.add_argument("--sequences", nargs="+", metavar="XX", default=None,
                        help="sequences to generate (default: test 00 09 and training 01-04)")
    parser.add_argument("--seed", type=seed, default=None, help="random seed (default 0)")
    parser.add_argument("--data-version", metavar="V", default=None,
                        help="synthetic data version (default: the newest, 6; 5 stays available)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def main(args: argparse.Namespace) -> int:
    from safl_bench import synth

    seed = synth.DEFAULT_SEED if args.seed is None else args.seed
    if seed < 0:
        raise DataError(f"--seed must be >= 0, got {seed}")
    version = synth.check_version(args.data_version or synth.GENERATOR_VERSION)
    root = Path(args.out).expanduser() if args.out else synth.default_root(seed, version)
    sequences = list(args.sequences) if args.sequences else list(synth.ALL_SEQUENCES)
    for name in sequences:
        if name not in synth.KNOWN_SEQUENCES:
            raise DataError(f"unknown synthetic sequence {name!r}; known: {' '.join(synth.KNOWN_SEQUENCES)}")
    start = time.perf_counter()
    todo = [n for n in sequences if not synth.is_current(root, n, seed, version=version)]
    synth.ensure(root, sequences, seed=seed, progress=not args.quiet, version=version)
    took = time.perf_counter() - start
    done = ", ".join(sequences)
    if todo:
        print(f"generated {', '.join(todo)} in {took:.1f} s; sequences {done} are in {root}")
    else:
        print(f"sequences {done} already up to date in {root}")
    return 0
