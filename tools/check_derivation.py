"""Check on real cells that a record derived from a superseded task version equals a recompute.

For each sampled (method, old task, seed), compute the cell in full under the old task and under
the task that replaced it, in one process on this host (`safl_bench.run.runner.run_grid`), derive
the new record from the old one (`safl_bench.results.derive.derive_record`) and compare every
measure, curve and per-query outcome of both matching modes with the new one's recompute; exits 1
on any difference. Each line also says how far the committed record of the old task (`--records`)
lies from its recompute here: a host with other vector instructions sums floats in another
order, so the learned networks' confidences move in the last bits and some tied or near-tied
matches flip. That is reproducibility across hosts, not derivation. The sample is given on the
command line; docs/reference/records.md quotes the run of 2026-12-04.

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
    sources = {registry[t].source for t in new_ids}
    if len(sources) != 1:
        parser.error(f"give tasks of one data source per run, got {sorted(sources)}")
    source = sources.pop()
    methods = [make_method(m, source=source) for m in args.method]  # the weights the CLI picks
    bad = 0
    with tempfile.TemporaryDirectory() as scratch:
        options = {}
        computed = {}
        for side, ids in (("old", args.task), ("new", new_ids)):
            options[side] = RunOptions(results_dir=Path(scratch) / side, bev_root=args.bev_root,
                                       kitti_root=args.kitti_root, progress=False,
                                       timing_frames=2, timing_repeats=1)
            for outcome in run_grid(methods, ids, options[side], seeds=seeds, log=lambda m: None):
                if outcome.record is None or outcome.status != "computed":
                    print(f"{outcome.task} seed {outcome.seed}: {outcome.status} {outcome.message}")
                    bad += 1
                    continue
                r = outcome.record
                computed[side, r.method.name, r.method.version, r.task.id, r.seed] = r
        for (side, name, version, new_id, seed), new in sorted(computed.items()):
            if side != "new":
                continue
            old_id = args.task[new_ids.index(new_id)]
            recomputed_old = computed.get(("old", name, version, old_id, seed))
            if recomputed_old is None:
                continue
            derived = derive_record(recomputed_old, registry[new_id])
            diffs = [mode for mode in new.results if new.results[mode] != derived.results[mode]]
            bad += bool(diffs)
            committed = load_record(record_path(args.records, name, version, old_id, seed))
            host = []
            for mode in ("sequence", "single_frame"):
                a = committed.results[mode]
                b = recomputed_old.results[mode]
                assert a.queries is not None and b.queries is not None
                dconf = max((abs(x - y) for x, y in zip(a.queries.confidence, b.queries.confidence,
                                                        strict=True)
                             if x is not None and y is not None), default=0.0)
                labels = sum(x != y for x, y in zip(a.queries.label, b.queries.label, strict=True))
                dr = 100 * (b.metrics.recall_at_100_precision - a.metrics.recall_at_100_precision)
                host.append(f"{mode}: max |d confidence| {dconf:.2g}, {labels} labels, "
                            f"R@100%P {dr:+.1f}")
            verdict = "equal" if not diffs else f"DIFFER in {', '.join(diffs)}"
            print(f"{name}@{version}  {new_id}  seed {seed}: derived {verdict} to the recompute "
                  f"({derived.results['sequence'].metrics.n_queries} queries); the committed "
                  f"{old_id} record against its recompute here: {'; '.join(host)}", flush=True)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
