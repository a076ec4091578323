"""`safl-bench list methods`: every registered version of every descriptor method, which one a
bare name runs on each data source, the weights each version ships (per data source) and where
each comes from."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from safl_bench.cli.list_tasks import format_table
from safl_bench.methods.method import MethodInfo, list_methods, resolve_method, shipped_weights_path

HELP = ("list the registered descriptor methods, every version (name, version, which one a bare "
        "name means, input, shipped weights per source, origin)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """--verbose, --json."""
    parser.add_argument("--verbose", "-v", action="store_true", help="add the weights files and a description")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")


def shipped_by_source(info: MethodInfo) -> dict[str, Path] | None:
    """The weights files this version ships, per data source they are picked for ("synth": the
    synthetic default's, the fallback of every source; "published": the published weights of a
    method not trained here, e.g. BEVPlace's); {} when it ships none, None for a method that
    takes no weights (or a plug-in that failed to load)."""
    from safl_bench.tasks.spec import SOURCES

    cls = info.cls
    if info.error is not None or cls is None or not (cls.trainable or getattr(cls, "ships_weights", False)):
        return None
    default = shipped_weights_path(cls)
    if not cls.trainable:
        return {"published": default} if default is not None else {}
    out = {"synth": default} if default is not None else {}
    for source in SOURCES:
        path = shipped_weights_path(cls, source)
        if source != "synth" and path is not None and path != default:
            out[source] = path
    return out


def main(args: argparse.Namespace) -> int:
    """Print the table (plug-ins that failed to load are listed with their error)."""
    from safl_bench.tasks.spec import SOURCES

    infos = list_methods(include_broken=True, all_versions=True)
    newest = {i.name: i.version for i in list_methods()}
    # what a bare name runs on each source (`resolve_method`: a learned method's newest version
    # with weights for it)
    runs = {(i.name, s): resolve_method(i.name, s).partition("@")[2]
            for i in infos if i.error is None and newest.get(i.name) == i.version for s in SOURCES}
    rows = []
    for info in infos:
        shipped = shipped_by_source(info)
        several = sum(i.name == info.name for i in infos) > 1
        bare_on = [s for s in SOURCES if runs.get((info.name, s)) == info.version]
        if not several:
            select = info.name
        elif not bare_on:
            select = f"{info.name}@{info.version}"
        elif len(bare_on) == len(SOURCES):
            select = f"{info.name} or {info.name}@{info.version}"
        else:
            select = f"{info.name}@{info.version} ({info.name} on {', '.join(bare_on)})"
        rows.append({
            "name": info.name,
            "version": info.version,
            "select": select,
            "bare_name": newest.get(info.name) == info.version,
            "bare_name_runs_on": bare_on,
            "input": info.input_kind,
            "from": info.origin if info.error is None else f"{info.origin}: FAILED TO LOAD: {info.error}",
            "description": info.summary,
            "weights": None if shipped is None else {s: p.name for s, p in shipped.items()},
        })
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0

    def weights(row: dict[str, object], files: bool) -> str:
        shipped = row["weights"]
        if not isinstance(shipped, dict):
            return "-"
        if not shipped:
            return "none shipped"
        return ", ".join(f"{s}: {f}" if files else s for s, f in shipped.items())

    keys = ["name", "version", "select", "input", "weights", "from"] + (["description"] if args.verbose else [])
    table = [[weights(r, args.verbose) if k == "weights" else str(r[k]) for k in keys] for r in rows]
    print(format_table(table, keys))
    print("A bare name runs, on each data source, the newest version with weights for it (a "
          "method that learns nothing: its newest); name@VERSION selects that one. weights: the "
          "data each version's shipped weights were trained for (synth: the synthetic default's, "
          "used where no source has its own; bev: real KITTI top views; published: its authors').")
    return 0
