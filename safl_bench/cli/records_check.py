"""`safl-bench records check DIR`: validate every result record under DIR.

Each file that is not a valid record (unreadable, not JSON, against the schema of
`safl-bench records schema`) is named in one line with the field at fault, as are duplicates and
records of older metrics versions that cannot be rescored; the status is 2 when any file is not
a valid record, else 0.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "validate the result records under a folder: one line per file that cannot be used"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """DIR."""
    parser.add_argument("folder", metavar="DIR", help="a results folder (records at <method>@<version>/<task>/seed-<n>.json)")


def main(args: argparse.Namespace) -> int:
    from safl_bench.errors import DataError
    from safl_bench.results.records import load_records

    folder = Path(args.folder)
    if not folder.is_dir():
        raise DataError(f"records folder {folder} does not exist or is not a directory")
    records, problems = load_records(folder)
    for problem in problems:
        print(f"safl-bench: {'error' if problem.corrupt else 'warning'}: {problem}", file=sys.stderr)
    print(f"{len(records)} valid records under {folder}; {len(problems)} files not used")
    return 2 if any(p.corrupt for p in problems) else 0
