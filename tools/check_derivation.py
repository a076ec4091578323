"""Check on real cells that a record derived from a superseded task version equals a recompute.

For each sampled (method, old task, seed) of a records folder, derive the record of the task
that replaced it (`safl_bench.results.derive.derive_record`) and compute the same cell in full
under the new task into a scratch folder (`safl_bench.run.runner.run_grid`); then compare every
measure, curve and per-query outcome of both matching modes. Prints one line per cell and exits
1 on any difference. The sample is given on the command line; docs/reference/records.md quotes
the run of 2026-12-04.

    python tools/check_derivation.py --records leaderboard/records \
        --method sad@1 --method stable_afl@1 --method bigan@1 \
        --task SAFL/BEVKITTI00-T1R1-v0 --task SAFL/Synth00-T20R2-v4 --seed 0 \
        --bev-root ../shared/kitti-topviews
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--records", required=True, help="folder of the old versions' records")
    parser.add_argument("--method", action="append", required=True, help="name@version")
    parser.add_argument("--task", action="append", required=True, help="a superseded task id")
    parser.add_argument("--seed", action="append", type=int, default=None)
    parser.add_argument("--bev-root", default=None)
    parser.add_argument("--kitti-root", default=None)
    args = parser.parse_args()
    warnings.simplefilter("ignore")  # "superseded" warnings: the old ids are asked for on purpose

    from safl_bench.methods.method import make_method
    from safl_bench.results.derive import derive_record
    from safl_bench.results.records import load_record, record_path
    from safl_bench.run.runner import RunOptions, run_grid
    from safl_bench.tasks.builtin import successor
    from safl_bench.tasks.registry import registry

    seeds = args.seed or [0]
    new_ids = []
    for task_id in args.task:
        new_id = successor(task_id)
        if new_id is None:
            parser.error(f"{task_id} has no successor task")
        new_ids.append(new_id)
    methods = [make_method(m) for m in args.method]
    bad = 0
    with tempfile.TemporaryDirectory() as scratch:
        options = RunOptions(results_dir=Path(scratch), bev_root=args.bev_root,
                             kitti_root=args.kitti_root, progress=False, timing_frames=2,
                             timing_repeats=1)
        for outcome in run_grid(methods, new_ids, options, seeds=seeds, log=lambda m: None):
            seed = outcome.seed
            if outcome.record is None or outcome.status != "computed":
                print(f"{outcome.task} seed {seed}: {outcome.status} {outcome.message}")
                bad += 1
                continue
            new = outcome.record
            old_id = next(o for o, n in zip(args.task, new_ids, strict=True) if n == new.task.id)
            old = load_record(record_path(args.records, new.method.name, new.method.version,
                                          old_id, seed))
            derived = derive_record(old, registry[new.task.id])
            diffs = [mode for mode in new.results if new.results[mode] != derived.results[mode]]
            r100 = {m: derived.results[m].metrics.recall_at_100_precision for m in derived.results}
            verdict = "equal" if not diffs else f"DIFFER in {', '.join(diffs)}"
            print(f"{new.method.name}@{new.method.version}  {new.task.id}  seed {seed}: "
                  f"derived {verdict} to the recompute ({derived.results['sequence'].metrics.n_queries} "
                  f"queries; R@100%P sequence {100 * r100['sequence']:.1f}, single-frame "
                  f"{100 * r100['single_frame']:.1f})", flush=True)
            bad += bool(diffs)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
