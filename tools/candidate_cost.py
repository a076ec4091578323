"""What the candidate search costs in accuracy: exact records against candidate records, paired.

    python tools/candidate_cost.py --method stable_afl@1 --exact DIR \
        --candidates 10=DIR10 --candidates 25=DIR25 --task 'SAFL/BEVKITTI00-T*-v1' ...

For each group of tasks (one --task pattern; the paper protocol's twelve conditions, say) and
each K: every measure's mean over the group's cells (each cell the mean over its seeds) for the
exact matcher, for the candidate search, and their paired difference, each with its 95 %
interval: the same two-level block bootstrap over seeds and queries as the board
(`safl_bench.evaluation.uncertainty`), the replicates of a group's cells averaged, so the
interval is that of the group mean. Prints a Markdown table; both matching modes.
"""

from __future__ import annotations

import argparse
import fnmatch
from pathlib import Path

import numpy as np

MEASURES = (("recall_at_1", "Recall@1"), ("recall_at_100_precision", "R@100%P"),
            ("f1_max", "F1max"))


def _interval(point: float, values: np.ndarray) -> str:
    finite = values[np.isfinite(values)]
    if not finite.size:
        return f"{100 * point:.1f} [n/a]"
    lo, hi = np.quantile(finite, [0.025, 0.975])
    return f"{100 * point:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--method", required=True, help="NAME@VERSION")
    ap.add_argument("--exact", required=True, type=Path)
    ap.add_argument("--candidates", action="append", required=True, metavar="K=DIR")
    ap.add_argument("--task", action="append", required=True, metavar="PATTERN")
    ap.add_argument("--label", action="append", default=[], metavar="TEXT",
                    help="a name for each --task pattern, in order")
    args = ap.parse_args(argv)

    from safl_bench.evaluation.uncertainty import sample
    from safl_bench.results.records import MODES, load_records

    name, _, version = args.method.partition("@")

    def cells(folder: Path) -> dict[tuple[str, int], object]:
        records, _ = load_records(folder)
        return {(r.task.id, r.seed): r for r in records
                if r.method.name == name and r.method.version == version}

    exact = cells(args.exact)
    print(f"{args.method}: exact matcher against the candidate search, paired over the same "
          "cells, seeds and queries; mean over the group's cells [95 % interval]; values in %")
    print()
    print("| tasks | K | mode | " + " | ".join(
        f"{label} exact | {label} candidates | {label} difference" for _, label in MEASURES) + " |")
    print("|" + "---|" * (3 + 3 * len(MEASURES)))
    for g, pattern in enumerate(args.task):
        label = args.label[g] if g < len(args.label) else pattern
        tasks = sorted({t for t, _ in exact if fnmatch.fnmatch(t, pattern)})
        for item in args.candidates:
            k, _, folder = item.partition("=")
            cand = cells(Path(folder))
            for mode in MODES:
                sums: dict[str, list[tuple[float, np.ndarray]]] = {}
                n_cells = 0
                for task in tasks:
                    seeds = sorted(s for t, s in exact if t == task and (t, s) in cand)
                    if not seeds:
                        continue
                    n_cells += 1
                    sides = [sample([side[(task, s)].results[mode].queries.outcomes()  # type: ignore[attr-defined]
                                     for s in seeds]) for side in (exact, cand)]
                    for measure, _ in MEASURES:
                        for key, smp in (("exact", sides[0]), ("cand", sides[1])):
                            sums.setdefault(f"{measure}/{key}", []).append(
                                (smp.points[measure], smp.values[measure]))
                if not n_cells:
                    continue
                row = [f"{label} ({n_cells} cells)", k, mode.replace("_", "-")]
                for measure, _ in MEASURES:
                    parts = {}
                    for key in ("exact", "cand"):
                        got = sums[f"{measure}/{key}"]
                        parts[key] = (float(np.mean([p for p, _ in got])),
                                      np.mean([v for _, v in got], axis=0))
                    diff = (parts["cand"][0] - parts["exact"][0], parts["cand"][1] - parts["exact"][1])
                    row += [_interval(*parts["exact"]), _interval(*parts["cand"]), _interval(*diff)]
                print("| " + " | ".join(row) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
