"""Option parsing shared by subcommands."""

from __future__ import annotations

import json
from typing import Any

from safl_bench.errors import ConfigError


def parse_key_values(items: list[str], flag: str) -> dict[str, Any]:
    """KEY=VALUE pairs -> dict; VALUE is JSON when it parses (numbers, true/false, lists), else
    a string. `flag` names the option in the error message."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"{flag} takes KEY=VALUE, got {item!r}")
        try:
            out[key] = json.loads(raw)
        except json.JSONDecodeError:
            out[key] = raw
    return out


def seed(text: str) -> int:
    """argparse type of a seed: an integer >= 0 (numpy's generators take no negative seeds)."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a seed is an integer >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"a seed is an integer >= 0, got {value}")
    return value


def seed_count(text: str) -> int:
    """argparse type of a number of seeds: an integer >= 1."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a number of seeds is an integer >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"a number of seeds is an integer >= 1, got {value}")
    return value


def add_parallel_arguments(parser: Any, what: str, ray_note: str = "") -> None:
    """--workers N and --ray ADDRESS (see `safl_bench.common.parallel`); `ray_note` ends
    --ray's help."""
    parser.add_argument("--workers", type=int, default=1, metavar="N",
                        help=f"{what} in N local worker processes (default 1: in this process)")
    parser.add_argument("--ray", metavar="ADDRESS",
                        help=f"{what} on a Ray cluster: 'auto' (the cluster this machine is in), "
                             "'ray://HOST:10001', or 'local' (start one here); needs "
                             f"safl-bench[ray]{ray_note}")


def parallel_from(args: Any) -> Any:
    """The `Parallel` the options ask for."""
    from safl_bench.common.parallel import Parallel

    return Parallel(workers=args.workers, ray_address=args.ray)


def add_bev_arguments(parser: Any) -> None:
    """--bev-root DIR and --bev-resolution M: the top-view image source (beside --kitti-root)."""
    from safl_bench.sources import BEV_ROOT_ENV, DEFAULT_RESOLUTION_M

    parser.add_argument("--bev-root", metavar="DIR",
                        help="top-view image folders (BEVPlace's layout: SEQ/imgs/*.png, SEQ/pose.txt): "
                             f"run their tasks (also ${BEV_ROOT_ENV}); not with --kitti-root")
    parser.add_argument("--bev-resolution", type=float, default=DEFAULT_RESOLUTION_M, metavar="M",
                        help="metres per pixel of those images (default %(default)s, BEVPlace's)")


def add_bev_rot_argument(parser: Any) -> None:
    """--bev-rot-root DIR: the second image folder of the rotated top-view tasks (commands that
    run tasks; the others read $SAFL_BEV_ROT_ROOT)."""
    from safl_bench.sources import BEV_ROT_ROOT_ENV

    parser.add_argument("--bev-rot-root", metavar="DIR",
                        help="rotated top views of the same sequences, same layout (BEVPlace's "
                             "data/KITTIRot: each scan yawed by its own random angle before its "
                             "image was made): the queries of the bev-rotated tasks, and their "
                             f"database where the task says so (also ${BEV_ROT_ROOT_ENV})")


def source_kind(args: Any) -> str:
    """The source the command's options select: "kitti", "bev" or "synth" (the default); both
    --kitti-root and --bev-root is an error."""
    from safl_bench.sources import real_roots

    kitti, bev = real_roots(getattr(args, "kitti_root", None), getattr(args, "bev_root", None))
    return "kitti" if kitti is not None else "bev" if bev is not None else "synth"
