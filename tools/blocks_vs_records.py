"""Recompute committed records with the matcher in query blocks and compare them number for number.

    python tools/blocks_vs_records.py --bev-root ../shared/kitti-topviews \
        leaderboard/records/*@1/SAFL__BEVKITTI00-T1R1-v1/seed-0.json

For each record: rebuild its method (`analysis.explain.rebuild_method`: the same weights and
parameters), open its task (the runner's own), evaluate it under the record's matcher settings
with blocks of `--block-rows` query rows (default 1024, the smallest that keeps the distance's
BLAS calls those of the whole matrix; `safl_bench.matching.blocks`) and as one block (the
dense path), and compare: the two evaluations' matches, scores and velocities number for
number, in both matching modes; and the blocked one's matched frames and true-place ranks
with the record's, with the largest difference of a confidence (a record made on another CPU
holds descriptors rounded by other vector kernels). One line per record; the status is 1 when
blocks and one block differ.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("records", nargs="+", type=Path)
    ap.add_argument("--bev-root", default=None)
    ap.add_argument("--bev-rot-root", default=None)
    ap.add_argument("--block-rows", type=int, default=1024)
    args = ap.parse_args(argv)

    from safl_bench.analysis.explain import rebuild_method
    from safl_bench.evaluation.cell import evaluate_method
    from safl_bench.matching.settings import MODES, EvaluationConfig
    from safl_bench.methods.method import method_input
    from safl_bench.methods.retrieval import is_retrieval
    from safl_bench.results.records import load_record
    from safl_bench.run import runner
    from safl_bench.tasks.registry import runnable_spec

    options = runner.RunOptions(results_dir=Path("."), bev_root=args.bev_root,
                                bev_rot_root=args.bev_rot_root, progress=False)
    bad = 0
    for path in args.records:
        record = load_record(path)
        label = f"{record.method.name}@{record.method.version} {record.task.id} seed {record.seed}"
        method = rebuild_method(record)
        if is_retrieval(method):
            print(f"{label}: skipped (a retrieval method: no difference matrix)")
            continue
        config = EvaluationConfig.from_dict(record.matcher)
        registered = runnable_spec(record.task.id)
        task = runner._task(registered, record.seed, options, False, method)
        kind = runner.view_kind(method, task)
        task.prepare([kind])
        queries, database = task.queries(kind), task.database(kind)
        ndb = len(database) if config.max_frames is None else min(len(database), config.max_frames)
        budget = args.block_rows * ndb * 4 * 3 / 1e6 * 1.0001  # exactly block-rows rows a block
        inputs = (method, method_input(method, queries), method_input(method, database),
                  task.truth_for(config))
        kw = dict(config=config, revisit=task.spec.protocol == "revisit",
                  context=task.spec.context_queries)
        t0 = time.perf_counter()
        ev = evaluate_method(*inputs, block_mb=budget, **kw)
        seconds = time.perf_counter() - t0
        whole = evaluate_method(*inputs, block_mb=1e9, **kw)  # one block: the dense path
        nq = len(ev.matches["sequence"].index)
        vs_whole, vs_record, drift = [], [], 0.0
        unheld: set[str] = set()
        for mode in MODES:
            a, b = ev.matches[mode], whole.matches[mode]
            vs_whole += [f"{mode} {k}" for k in ("index", "score", "velocity")
                         if not np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True)]
            held, got = record.results[mode].queries, ev.outcomes[mode]
            conf = np.array([-np.inf if c is None else c for c in held.confidence], float)
            if held.match is None:
                unheld.add("matched frames")
            elif not np.array_equal(np.asarray(held.match), np.asarray(got.match)):
                vs_record.append(f"{mode} match")
            if held.true_rank is not None:
                off = np.asarray(held.true_rank) != np.asarray(got.true_rank)
                if off.any():
                    vs_record.append(f"{mode} true_rank of {int(off.sum())} queries")
            fin = np.isfinite(conf) & np.isfinite(got.confidence)
            if not np.array_equal(np.isfinite(conf), np.isfinite(got.confidence)):
                vs_record.append(f"{mode} answered")
            if fin.any():
                drift = max(drift, float(np.abs(conf[fin] - got.confidence[fin]).max()))
        blocks = -(-nq // args.block_rows)
        print(f"{label} [{config.sequence.preset}]: {nq} queries, {blocks} block(s) of "
              f"{args.block_rows} against one: "
              f"{'identical' if not vs_whole else 'DIFFER in ' + ', '.join(vs_whole)}; against "
              f"the record: {'the same' if not vs_record else 'DIFFER in ' + ', '.join(vs_record)}"
              f"{' (it holds no ' + ', '.join(sorted(unheld)) + ')' if unheld else ''}, "
              f"confidence within {drift:.1e} ({seconds:.1f} s)", flush=True)
        bad += bool(vs_whole)
    return 1 if bad else 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    sys.exit(main())
