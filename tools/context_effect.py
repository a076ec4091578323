"""What the context queries change: each method's mean recall at 100 % precision and AUC of the
sequence matcher over the paper-protocol records of the task versions that scored every query,
before (as recorded) and after (derived under the versions that replaced them), and where the
most confident wrong match of each old cell lies.

    git worktree add /tmp/before 61486b0      # the last commit with the old versions' records
    python tools/context_effect.py /tmp/before/leaderboard/records

Prints Markdown; docs/reference/tasks.md ("Context queries") quotes its output.
"""

from __future__ import annotations

import argparse
import collections
import math
import warnings

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("records", help="a records folder holding the superseded versions' records")
    args = parser.parse_args()
    warnings.simplefilter("ignore")  # "superseded" warnings: the old ids are read on purpose

    from safl_bench.results.derive import derive_record
    from safl_bench.results.records import load_records
    from safl_bench.tasks.builtin import successor
    from safl_bench.tasks.registry import registry

    records, _ = load_records(args.records)
    rows: dict[tuple[str, str], dict[str, list[float]]] = collections.defaultdict(
        lambda: collections.defaultdict(list))
    first_wrong: collections.Counter[str] = collections.Counter()
    for record in records:
        new_id = successor(record.task.id)
        if record.task.protocol != "paper" or new_id is None:
            continue
        derived = derive_record(record, registry[new_id])
        source = "real KITTI 00" if record.task.source_kind == "bev" else "synthetic 00"
        key = (source, f"{record.method.name}@{record.method.version}")
        for tag, rec in (("before", record), ("after", derived)):
            m = rec.results["sequence"].metrics
            rows[key][f"{tag} r"].append(100 * m.recall_at_100_precision)
            rows[key][f"{tag} auc"].append(math.nan if m.auc is None else m.auc)
            rows[key][f"{tag} zero"].append(float(m.recall_at_100_precision == 0))
        queries = record.results["sequence"].queries
        assert queries is not None
        conf = np.array([-np.inf if c is None else c for c in queries.confidence])
        wrong = np.flatnonzero(np.array(queries.label) == -1)
        if not len(wrong):
            first_wrong["no wrong match"] += 1
        else:
            top = int(wrong[np.argmax(conf[wrong])])  # the first (lowest index) of tied maxima
            first_wrong["query 0" if top == 0 else "queries 1-9" if top < 10 else "query 10 on"] += 1
    print("| source | method | cells | R@100%P before | after | AUC before | after "
          "| cells at 0 before | after |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for (source, method), v in sorted(rows.items()):
        print(f"| {source} | {method} | {len(v['before r'])} | {np.mean(v['before r']):.1f} "
              f"| {np.mean(v['after r']):.1f} | {np.nanmean(v['before auc']):.3f} "
              f"| {np.nanmean(v['after auc']):.3f} | {int(sum(v['before zero']))} "
              f"| {int(sum(v['after zero']))} |")
    total = sum(first_wrong.values())
    print(f"\nThe most confident wrong match of the {total} old sequence cells: "
          + ", ".join(f"{k} in {n}" for k, n in sorted(first_wrong.items())) + ".")


if __name__ == "__main__":
    main()
