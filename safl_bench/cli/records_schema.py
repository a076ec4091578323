"""`safl-bench records schema`: the JSON Schema of a result record file.

Printed, or written to `--out FILE` (atomically); docs/reference/record.schema.json is this
output, and a test keeps it current. Other tools can validate records against it without
safl-bench.
"""

from __future__ import annotations

import argparse
import json

HELP = "print (or write with --out) the JSON Schema of a result record file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """--out."""
    parser.add_argument("--out", metavar="FILE", help="write the schema to FILE instead of printing it")


def schema_text() -> str:
    """The schema as written: indented JSON, sorted keys, one newline at the end."""
    from safl_bench.results.records import record_schema

    return json.dumps(record_schema(), indent=2, sort_keys=True) + "\n"


def main(args: argparse.Namespace) -> int:
    text = schema_text()
    if args.out:
        from safl_bench.common.atomic import atomic_write_text

        atomic_write_text(args.out, text)
        print(f"record schema: {args.out}")
    else:
        print(text, end="")
    return 0
