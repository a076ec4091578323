"""`safl-bench list matchers`: the matcher presets, what each is, and every setting of each."""

from __future__ import annotations

import argparse
import json

from safl_bench.cli.list_tasks import format_table

HELP = ("list the matcher presets (safl-bench run --matcher-preset NAME) with a description and "
        "every setting of each")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """--json."""
    parser.add_argument("--json", action="store_true", help="print JSON instead of tables")


def main(args: argparse.Namespace) -> int:
    """Print the presets, then one table: a row per setting, a column per preset, then each
    preset's every value with the file and line (or the part of the paper) it comes from."""
    from safl_bench.matching import presets as mp

    presets = [mp.get(name) for name in mp.names()]
    if args.json:
        print(json.dumps({p.name: {"description": p.description, "settings": mp.settings(p.config),
                                   "citations": {k: mp.citation(p, k) for k in mp.SETTINGS}}
                          for p in presets}, indent=2))
        return 0
    width = max(len(p.name) for p in presets)
    print("Matcher presets (safl-bench run --matcher-preset NAME; --matcher KEY=VALUE changes a "
          "setting on top; where each value comes from: pydoc safl_bench.matching.presets):")
    for p in presets:
        print(f"  {p.name.ljust(width)}  {p.description}")
    print()
    base = mp.settings(mp.get(mp.DEFAULT).config)
    rows = []
    for name in mp.SETTINGS:
        values = []
        for p in presets:
            value = mp.settings(p.config)[name]
            values.append(mp.format_value(value) + (" *" if value != base[name] else ""))
        rows.append([name, *values, mp.SETTING_HELP.get(name, "")])
    print(format_table(rows, ["setting", *[p.name for p in presets], "what it sets"]))
    print(f"* differs from {mp.DEFAULT}")
    print()
    print("Where each value comes from (file:line@commit of CNN-GAN/Top-Mapping, or the paper):")
    for p in presets:
        print(f"  {p.name}:")
        for name in mp.SETTINGS:
            print(f"    {name} = {mp.format_value(mp.settings(p.config)[name])}: {mp.citation(p, name)}")
    return 0
