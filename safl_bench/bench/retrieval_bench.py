"""Benchmark of a retrieval method in the harness (issue 38, "How fast"): the method's own calls
against the harness's whole evaluation of the same cell.

    safl-bench bench retrieval [--method map_closures] [--task ID] [--bev-root DIR] [--repeats 3]

On the task's views (read once, before any timing), each repeat times, back to back:

* own: the method's own calls alone, on the maps already converted to what it reads
  (`own_calls`, e.g. MapClosures: a fresh pipeline and ``get_closures`` of every map in the
  order the harness feeds them; density map, ORB, search and RANSAC, nothing else);
* harness: `safl_bench.evaluation.cell.evaluate_method` on the same views: the same calls plus
  everything the harness adds (the view adapter, the method's input checks, ranking under the
  candidate rule, Recall@N and every measure).

Printed: the medians and the harness's overhead, harness / own - 1 (the issue's bound: 10 %),
and how many scored queries each later repeat answered exactly as the first (MapClosures' RANSAC
is not seeded: this is how much that moves).
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench.errors import ConfigError
from safl_bench.methods.method import make_method
from safl_bench.methods.retrieval import is_retrieval

DEFAULT_METHOD = "map_closures"
DEFAULT_TASK = "SAFL/Synth00-Revisit-v6"


def run(method_name: str = DEFAULT_METHOD, task_id: str = DEFAULT_TASK, *,
        bev_root: str | None = None, kitti_root: str | None = None,
        repeats: int = 3) -> dict[str, Any]:
    """The figures (module docstring) of `method_name` on `task_id` (seed 0)."""
    from safl_bench.evaluation.cell import evaluate_method
    from safl_bench.run import runner
    from safl_bench.tasks import spec

    method = make_method(method_name)
    if not is_retrieval(method) or not hasattr(method, "own_calls"):
        raise ConfigError(f"bench retrieval times retrieval methods with own_calls(); "
                          f"{method_name!r} is not one")
    options = runner.RunOptions(results_dir=Path("."), bev_root=bev_root, kitti_root=kitti_root,
                                progress=False)
    registered = spec(task_id)
    task = runner._task(registered, registered.seed, options, False, method)
    kind = runner.view_kind(method, task)
    task.prepare([kind])
    queries, database = task.queries(kind), task.database(kind)
    truth = task.truth_for(options.evaluation)
    revisit = task.spec.protocol == "revisit"
    own, harness, answers = [], [], []
    for _ in range(repeats):
        own.append(method.own_calls(queries, database, same_frames=revisit))
        t0 = time.perf_counter()
        ev = evaluate_method(method, queries, database, truth, config=options.evaluation,
                             revisit=revisit, context=task.spec.context_queries)
        harness.append(time.perf_counter() - t0)
        answers.append(ev.outcomes["single_frame"])
    first = answers[0]
    assert first.match is not None  # the label layer always keeps the matched frames
    same = [int(np.count_nonzero((a.match == first.match) & (a.confidence == first.confidence)))
            for a in answers[1:]]
    own_s, harness_s = statistics.median(own), statistics.median(harness)
    return {"method": f"{method.name}@{method.version}", "task": task_id, "views": kind,
            "n_queries": len(queries), "n_database": len(database), "repeats": repeats,
            "own_s": own_s, "harness_s": harness_s, "own_runs_s": own, "harness_runs_s": harness,
            "overhead": harness_s / own_s - 1 if own_s > 0 else None,
            "scored_queries": len(first.match), "answered_first": int(np.count_nonzero(first.match >= 0)),
            "same_answer_as_first": same}


def format_results(r: dict[str, Any]) -> str:
    """The benchmark's lines."""
    overhead = "n/a" if r["overhead"] is None else f"{100 * r['overhead']:+.1f} %"
    return "\n".join([
        f"{r['method']} on {r['task']} ({r['n_queries']} queries, {r['n_database']} database "
        f"frames, {r['views']} views), median of {r['repeats']}:",
        f"  the method's own calls   {r['own_s']:8.2f} s  "
        f"({1e3 * r['own_s'] / max(r['n_queries'], 1):.2f} ms a query)",
        f"  the harness, whole cell  {r['harness_s']:8.2f} s",
        f"  harness overhead         {overhead} (bound: +10 %)",
        f"  repeats answering exactly as the first (frame and confidence): "
        f"{', '.join(str(n) for n in r['same_answer_as_first']) or '-'} of {r['scored_queries']} "
        f"scored queries ({r['answered_first']} answered in the first)",
    ])
