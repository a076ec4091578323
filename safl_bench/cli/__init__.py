"""The `safl-bench` command line.

Each subcommand lives in its own module in this package and exposes `HELP`,
`add_arguments(parser)` and `main(args) -> int`; `COMMANDS` below names them. Only the module of
the subcommand being run is imported. Errors the user can fix (`SaflError`) print one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from types import ModuleType
from typing import Any, NoReturn

from safl_bench.errors import SaflError

# command -> (module in this package, one-line help); groups map to a dict of their subcommands.
# The help lines live here so that `safl-bench --help` and the parser for one subcommand never
# import the other subcommands' modules (and their numba/matplotlib/torch imports).
Command = tuple[str, str]
COMMANDS: dict[str, Command | dict[str, Command]] = {
    "data": {
        "synth": ("data_synth", "generate the embedded synthetic default in the KITTI layout"),
        "show": ("data_show", "draw a route, its revisits, scans and top-view maps to a PNG"),
        "prepare": ("data_prepare", "build and cache top-view maps (synthetic default or KITTI)"),
        "loops": ("data_loops", "export ground-truth loop pairs of a KITTI poses file as CSV"),
        "export": ("data_export", "write a scan sequence's top views as images in BEVPlace's layout"),
        "fidelity": ("data_fidelity", "compare the synthetic default with real top-view images: statistics, curves, rankings"),
        "resampling": ("data_resampling", "resampled queries (empty corners) against re-rendered ones, paired, per method and condition"),
    },
    "list": {
        "tasks": ("list_tasks", "list the registered benchmark tasks"),
        "methods": ("list_methods", "list the registered descriptor methods"),
        "matchers": ("list_matchers", "list the matcher presets with every setting"),
    },
    "records": {
        "schema": ("records_schema", "print (or write with --out) the JSON Schema of a result record file"),
        "check": ("records_check", "validate the result records under a folder, one line per bad file"),
        "migrate": ("records_migrate", "derive the records of the current task versions from those of the versions they replaced"),
    },
    "run": ("run", "run a method on benchmark tasks and store result records"),
    "explain": ("explain", "draw one cell's matrices, matches, scores and worst false positives to a PNG"),
    "slam": ("slam", "what one revisit cell's loop closures do to the trajectory: GTSAM back-ends, ATE/RPE (evo)"),
    "train": ("train", "train a learned method (BiGAN, Stable-AFL) on the training sequences"),
    "train-curve": ("train_curve", "evaluate a training run's snapshots: AUC against steps (Figure 14)"),
    "compare": ("compare", "compare two methods task by task, paired, with 95 %% intervals and a verdict"),
    "leaderboard": ("leaderboard", "regenerate leaderboard tables, figures and web pages from records"),
    "bench": ("bench", "print speed figures: descriptor ms/frame per method, matcher time and memory"),
}

GROUP_HELP = {
    "data": "make, inspect and prepare datasets (synthetic default or KITTI)",
    "list": "list registered tasks or methods",
    "records": "the result records: their JSON Schema, a check of a folder of them, and their move to new task versions",
}


def _load(name: str) -> ModuleType:
    return importlib.import_module(f"safl_bench.cli.{name}")


def _selected(argv: Sequence[str]) -> list[str]:
    """The command words of `argv` (leading non-option tokens), e.g. ['data', 'prepare']."""
    words: list[str] = []
    for token in argv:
        if token.startswith("-"):
            break
        words.append(token)
    return words


def _add(sub: Any, name: str, command: Command, selected: bool) -> None:
    module_name, help_line = command
    if not selected:  # listed in --help, but its module is not imported
        sub.add_parser(name, help=help_line)
        return
    module = _load(module_name)
    p = sub.add_parser(name, help=help_line, description=getattr(module, "HELP", help_line))
    module.add_arguments(p)
    p.set_defaults(_handler=module.main)


class _Parser(argparse.ArgumentParser):
    """argparse's parser whose usage errors are one line (what is wrong and where the help is),
    exit 2, instead of the whole usage text before the message."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser; only the subcommand named in `argv` is imported (all if None)."""
    from safl_bench import __version__

    words = _selected(argv) if argv is not None else None
    parser = _Parser(
        prog="safl-bench",
        description="Benchmark LiDAR loop-closure-detection descriptors (Stable-AFL and others).",
    )
    parser.add_argument("--version", action="version", version=f"safl-bench {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, target in COMMANDS.items():
        chosen = words is None or (len(words) > 0 and words[0] == name)
        if isinstance(target, dict):
            group = sub.add_parser(name, help=GROUP_HELP[name], description=GROUP_HELP[name])
            gsub = group.add_subparsers(dest="subcommand", metavar="SUBCOMMAND", required=True)
            for sub_name, command in target.items():
                picked = words is None or (chosen and len(words) > 1 and words[1] == sub_name)
                _add(gsub, sub_name, command, picked)
        else:
            _add(sub, name, target, chosen)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `safl-bench` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser(argv).parse_args(argv)
    try:
        return int(args._handler(args) or 0)
    except SaflError as exc:
        print(f"safl-bench: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `safl-bench list tasks | head`
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print("safl-bench: interrupted; finished work is kept and a rerun resumes", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
