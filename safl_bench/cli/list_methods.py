"""`safl-bench list methods`: the registered descriptor methods and where each comes from."""

from __future__ import annotations

import argparse
import json

from safl_bench.cli.list_tasks import format_table
from safl_bench.methods.method import list_methods, shipped_weights_path

HELP = "list the registered descriptor methods (name, version, input, origin)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """--verbose, --json."""
    parser.add_argument("--verbose", "-v", action="store_true", help="add a description and the shipped weights")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")


def main(args: argparse.Namespace) -> int:
    """Print the table (plug-ins that failed to load are listed with their error)."""
    infos = list_methods(include_broken=True)
    rows = []
    for info in infos:
        if info.error is not None:
            weights = "-"
        elif info.cls is not None and (info.cls.trainable or getattr(info.cls, "ships_weights", False)):
            shipped = [p for p in (shipped_weights_path(info.cls, s) for s in (None, "bev")) if p]
            weights = ", ".join(dict.fromkeys(p.name for p in shipped)) or "none shipped"
        else:
            weights = "-"
        rows.append({
            "name": info.name,
            "version": info.version,
            "input": info.input_kind,
            "from": info.origin if info.error is None else f"{info.origin}: FAILED TO LOAD: {info.error}",
            "description": info.summary,
            "weights": weights,
        })
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    keys = ["name", "version", "input", "from"] + (["weights", "description"] if args.verbose else [])
    print(format_table([[r[k] for k in keys] for r in rows], keys))
    return 0
