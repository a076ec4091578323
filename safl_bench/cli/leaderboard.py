"""`safl-bench leaderboard`: regenerate the leaderboard's tables and figures from result records.

A record file that is not a valid record (not JSON, or against the schema,
`safl-bench records schema`) is named in one line with the field at fault; the leaderboard is
built from the other records and the command exits with status 2.

Defaults make the leaderboard directory self-contained: it holds its records (records/), the
records of the same tasks under other matcher presets (preset-records/<preset>/: a record's path
does not name its preset) and training logs (training-logs/) beside the generated tables and
figures, the records of checkpoints selected on the test set (selected-records/: shown only in
Table II, in rows of their own) and Table II's variants (experiments/table2/<name>/: records with
one thing changed and a variant.json naming it), so running the command at the root of a safl-bench checkout rebuilds the committed
leaderboard exactly. It also writes the web pages (OUT/site/index.html, opened from disk) and,
when OUT is a checkout's leaderboard/, the headline block of that checkout's README.md and the
generated blocks of its guides (`safl_bench.leaderboard.guides`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from safl_bench.leaderboard import build_leaderboard, table2
from safl_bench.leaderboard.guides import update_guides
from safl_bench.leaderboard.headline import update_readme
from safl_bench.leaderboard.readme import replace_block
from safl_bench.matching.presets import label
from safl_bench.results.records import Problem, ResultRecord, load_records

SELECTED_RECORDS = "selected-records"
TABLE2_VARIANTS = "experiments/table2"
#: The folders of OUT (besides the records) that parts of the board are built from, and those
#: parts: a board built where one is missing names it (`main`).
BOARD_INPUTS: tuple[tuple[str, str], ...] = (
    ("preset-records", "the tables by matcher preset and Table II"),
    (SELECTED_RECORDS, "Table II's rows of checkpoints selected on the test set"),
    (TABLE2_VARIANTS, "Table II's variants"),
    ("experiments/matcher-scaling", "the matcher's speed page"),
    ("training-logs", "the training curves"),
)

HELP = "regenerate the leaderboard (Markdown/CSV tables, PNG figures, web pages) from result records"


def default_out_dir(cwd: Path | None = None) -> Path:
    """leaderboard/ of the enclosing safl-bench checkout if there is one, else ./leaderboard."""
    here = (cwd or Path.cwd()).resolve()
    for directory in (here, *here.parents):
        pyproject = directory / "pyproject.toml"
        if pyproject.is_file() and _is_safl_bench(pyproject):
            return directory / "leaderboard"
    return here / "leaderboard"


def _is_safl_bench(pyproject: Path) -> bool:
    try:
        text = pyproject.read_text(encoding="utf-8")
    except OSError:
        return False
    return 'name = "safl-bench"' in text


def load_preset_records(out: Path) -> tuple[list[ResultRecord], list[Problem]]:
    """The records under OUT/preset-records/<preset>/ (other matcher presets' runs)."""
    folder = out / "preset-records"
    records: list[ResultRecord] = []
    problems: list[Problem] = []
    for sub in sorted(p for p in folder.iterdir() if p.is_dir()) if folder.is_dir() else []:
        found, bad = load_records(sub)
        records += found
        problems += bad
    return records, problems


def default_preset_only(records: list[ResultRecord], folder: Path
                        ) -> tuple[list[ResultRecord], list[Problem]]:
    """(the records of the default matcher preset, one Problem per other record): the records
    folder holds the default preset's runs, so that no table mixes two presets; a record made
    under another (e.g. ``paper-r10``, the default before the window rule) is refused with the
    command that recomputes it under the default, or the folder it belongs in."""
    from safl_bench.matching.presets import DEFAULT
    from safl_bench.results.records import record_path, rerun_command

    kept: list[ResultRecord] = []
    refused: list[Problem] = []
    for record in records:
        name = label(record.matcher)
        if name == DEFAULT:
            kept.append(record)
            continue
        path = record_path(folder, record.method.name, record.method.version, record.task.id,
                           record.seed)
        refused.append(Problem(path, f"made under matcher preset {name!r}, not the default "
                               f"{DEFAULT!r} this folder holds; recompute it with: "
                               f"{rerun_command(record)} --results {folder}, or move it to "
                               f"preset-records/{name}/"))
    return kept, refused


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """--results, --out, --training-logs, --no-figures."""
    parser.add_argument(
        "--out",
        metavar="DIR",
        help="leaderboard directory to regenerate (default: leaderboard/ of the safl-bench "
        "checkout you are in, else ./leaderboard)",
    )
    parser.add_argument(
        "--results",
        metavar="DIR",
        help="result records to build from (default: OUT/records, the leaderboard's own records)",
    )
    parser.add_argument(
        "--training-logs",
        metavar="DIR",
        help="training logs DIR/<method>/train_log.jsonl for the training-stability figure "
        "(default: OUT/training-logs)",
    )
    parser.add_argument(
        "--no-figures", action="store_true", help="write the tables only (faster; no PNGs)"
    )
    parser.add_argument(
        "--no-site", action="store_true", help="do not write the web pages (OUT/site/)"
    )


def main(args: argparse.Namespace) -> int:
    out = Path(args.out) if args.out else default_out_dir()
    results = Path(args.results) if args.results else out / "records"
    logs = Path(args.training_logs) if args.training_logs else out / "training-logs"
    records, problems = load_records(results)
    records, other_preset = default_preset_only(records, results)
    problems += other_preset
    preset_records, bad = load_preset_records(out)
    shown = {id(r): _shown(out / "preset-records" / label(r.matcher)) for r in preset_records}
    # checkpoints selected on the test set: only Table II shows them, in rows of their own
    selected, bad_selected = load_records(out / SELECTED_RECORDS)
    shown.update({id(r): _shown(out / SELECTED_RECORDS) for r in selected})
    variants, bad_variants = table2.load_variants(out / TABLE2_VARIANTS)
    bad = [*bad, *bad_selected, *bad_variants]
    results_shown = _shown(results)
    problems += bad
    for problem in problems:
        severity = "error" if problem.corrupt else "warning"
        print(f"safl-bench: {severity}: skipped record {problem}", file=sys.stderr)
    from safl_bench.results.derive import superseded_note

    for folder, found in ((results, records), (out / "preset-records", preset_records),
                          (out / SELECTED_RECORDS, selected)):
        note = superseded_note(found, folder)
        if note is not None:
            print(f"safl-bench: note: {note}", file=sys.stderr)
    report = build_leaderboard(
        records,
        out,
        training_logs=logs,
        skipped=problems,
        skipped_base=results,
        figures=not args.no_figures,
        preset_records=preset_records,
        selected_records=selected,
        table2_variants=variants,
        site=not args.no_site,
        records_folder=lambda record: shown.get(id(record), results_shown),
    )
    for problem in report.problems:
        if problem not in problems:
            print(f"safl-bench: warning: {problem}", file=sys.stderr)
    print(
        f"leaderboard: {len(records)} records from {results} -> {out} "
        f"({len(report.written)} files written, {len(report.removed)} stale files removed)"
    )
    absent = [f"{folder}/ ({what})" for folder, what in BOARD_INPUTS
              if not (logs if folder == "training-logs" else out / folder).is_dir()]
    if absent:  # a board built elsewhere (--out) says what it leaves out, never silently
        print(f"safl-bench: note: {out} has no {'; no '.join(absent)}: this board leaves them "
              "out; copy those folders from a checkout's leaderboard/ to include them",
              file=sys.stderr)
    if report.headline is not None:
        print()
        print(report.headline.markdown(level=3), end="")
    print(f"\nindex: {out / 'index.md'}")
    if not args.no_site:
        print(f"site: {out / 'site' / 'index.html'}")
    readme = out.parent / "README.md"
    if out.resolve() == default_out_dir().resolve() and readme.is_file():
        if report.headline is not None and update_readme(readme, report.headline, report.headline_records):
            print(f"README headline: {readme}")
        if report.table2:
            side, rel = report.table2[min(report.table2)]
            block = table2.readme_block(side, rel)
            if replace_block(readme, table2.README_START, table2.README_END, block, "Table II"):
                print(f"README Table II: {readme}")
        for guide in update_guides(out.parent, report):
            print(f"guide blocks: {guide}")
    # built from the other records; a record that is not valid (bad JSON, against the schema) is
    # an error the user has to fix, so the command says so in its status
    return 2 if any(problem.corrupt for problem in problems) else 0


def _shown(path: Path) -> str:
    """`path` as a reader at the checkout's root names it (relative when it is inside)."""
    root = default_out_dir().parent.resolve()
    try:
        return Path(path).resolve().relative_to(root).as_posix()
    except ValueError:
        return Path(path).as_posix()
