"""The `safl-bench` command line.

Each subcommand lives in its own module in this package and exposes `HELP`,
`add_arguments(parser)` and `main(args) -> int`. `data` and `list` group further subcommands the
same way. Errors the user can fix (`SaflError`) print one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from types import ModuleType

from safl_bench.errors import SaflError

# command name -> module (relative to this package); groups map to a dict of their subcommands.
COMMANDS: dict[str, str | dict[str, str]] = {
    "data": {
        "synth": "data_synth",
        "show": "data_show",
        "prepare": "data_prepare",
        "loops": "data_loops",
    },
    "list": {"tasks": "list_tasks", "methods": "list_methods"},
    "run": "run",
    "train": "train",
    "leaderboard": "leaderboard",
}

GROUP_HELP = {
    "data": "make, inspect and prepare datasets (synthetic default or KITTI)",
    "list": "list registered tasks or methods",
}


def _load(name: str) -> ModuleType:
    return importlib.import_module(f"safl_bench.cli.{name}")


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser (imports every subcommand module)."""
    from safl_bench import __version__

    parser = argparse.ArgumentParser(
        prog="safl-bench",
        description="Benchmark LiDAR loop-closure-detection descriptors (Stable-AFL and others).",
    )
    parser.add_argument("--version", action="version", version=f"safl-bench {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, target in COMMANDS.items():
        if isinstance(target, dict):
            group = sub.add_parser(name, help=GROUP_HELP[name], description=GROUP_HELP[name])
            gsub = group.add_subparsers(dest="subcommand", metavar="SUBCOMMAND", required=True)
            for sub_name, module_name in target.items():
                module = _load(module_name)
                p = gsub.add_parser(sub_name, help=module.HELP, description=module.HELP)
                module.add_arguments(p)
                p.set_defaults(_handler=module.main)
        else:
            module = _load(target)
            p = sub.add_parser(name, help=module.HELP, description=module.HELP)
            module.add_arguments(p)
            p.set_defaults(_handler=module.main)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `safl-bench` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._handler(args) or 0)
    except SaflError as exc:
        print(f"safl-bench: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("safl-bench: interrupted; finished work is kept and a rerun resumes", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
