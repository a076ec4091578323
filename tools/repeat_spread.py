"""How much the repeated runs of an unseedable method's cells differ (MapClosures: RANSAC drawn
from std::random_device), from the records alone.

    python tools/repeat_spread.py leaderboard/records/map_closures@1

For every task folder with more than one run of a cell (`safl_bench.results.records.is_repeat`:
seeds other than the task's on a task where nothing is random), per matching mode: how many
queries' answers (matched frame and confidence) differ from the first run's, and the range of
F1max, recall at 100 % precision and Recall@1 over the runs. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from safl_bench.results.records import is_repeat, load_records

MEASURES = (("f1_max", "F1max", 3), ("recall_at_100_precision", "R@100%P", 1), ("recall_at_1", "R@1", 1))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("records", type=Path, help="a method's records folder, e.g. leaderboard/records/map_closures@1")
    args = ap.parse_args(argv)
    records, problems = load_records(args.records)
    for problem in problems:
        print(f"skipped: {problem}")
    cells: dict[str, list] = {}
    for record in records:
        cells.setdefault(record.task.id, []).append(record)
    print("| task | mode | runs | answers differing from run 0 | " + " | ".join(m[1] for m in MEASURES) + " |")
    print("|---|---|---:|---:|" + "---:|" * len(MEASURES))
    for task_id, runs in sorted(cells.items()):
        runs = sorted(runs, key=lambda r: r.seed)
        if len(runs) < 2 or not any(is_repeat(r) for r in runs):
            continue
        for mode in runs[0].results:
            first = runs[0].results[mode].queries
            if first is None:
                continue
            a = first.outcomes()
            differ = []
            for other in runs[1:]:
                q = other.results[mode].queries
                if q is None:
                    continue
                b = q.outcomes()
                same = (a.match == b.match) & ((a.confidence == b.confidence)
                                                | (np.isneginf(a.confidence) & np.isneginf(b.confidence)))
                differ.append(int((~same).sum()))
            spans = []
            for key, _, decimals in MEASURES:
                values = [getattr(r.results[mode].metrics, key) for r in runs]
                scale = 1 if decimals == 3 else 100
                lo, hi = min(values) * scale, max(values) * scale
                spans.append(f"{lo:.{decimals}f}" if lo == hi else f"{lo:.{decimals}f}–{hi:.{decimals}f}")
            print(f"| {task_id} | {mode} | {len(runs)} | {', '.join(map(str, differ)) or '—'} of "
                  f"{len(a.match)} | " + " | ".join(spans) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
