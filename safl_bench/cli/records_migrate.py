"""`safl-bench records migrate DIR`: move a results folder to the current task versions.

For every record of a task version that a current one replaced with the same data and matches
(the paper and BEVPlace protocols' versions that scored every query: `tasks.builtin.successor`),
write the record of the current version derived from it (`safl_bench.results.derive`: its
per-query outcomes with the new version's context queries dropped, every measure recomputed),
without recomputing anything. ``--remove`` deletes each old record once its successor exists,
so that the folder holds the current versions only; without it both stay, each in its own
tables. One line per record that cannot be derived (it is kept).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "derive the records of the current task versions from those of the versions they replaced"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """DIR, --remove, --force."""
    parser.add_argument("folder", metavar="DIR", help="a results folder (records at <method>@<version>/<task>/seed-<n>.json)")
    parser.add_argument("--remove", action="store_true",
                        help="delete each old record once the record of its successor exists")
    parser.add_argument("--force", action="store_true",
                        help="derive again where a record of the current version exists")


def main(args: argparse.Namespace) -> int:
    from safl_bench.errors import DataError
    from safl_bench.results.derive import migrate

    folder = Path(args.folder)
    if not folder.is_dir():
        raise DataError(f"records folder {folder} does not exist or is not a directory")
    done = migrate(folder, remove=args.remove, force=args.force)
    for line in done.kept:
        print(f"safl-bench: note: kept {line}", file=sys.stderr)
    print(f"{len(done.derived)} records derived, {len(done.removed)} old records removed, "
          f"{len(done.kept)} kept under {folder}")
    return 0
