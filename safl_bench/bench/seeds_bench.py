"""Benchmark of what a cell's seeds cost (issue 25): five seeds of a (method, task) cell against
one, and what the interval computation adds to a cell.

    safl-bench bench seeds --bev-root DIR [--method stable_afl@1 --method bigan@1] [--task ID]

For each method, each repeat times, back to back in this process: the cell at one seed; at five
seeds with the seeds sharing the cell's batch-1 timing and its database descriptors
(`RunOptions.share_seeds`, what `safl-bench run` does); and at five seeds each described and
timed on its own (`share_seeds=False`, the behaviour before). Every run starts from no records
and no cached views (a scratch `$SAFL_HOME` each, as `bench parallel` does), so a seed's cost
includes rendering its noisy queries and the first seed's includes reading the clean views; an
untimed one-seed run first warms the process (imports, compiled kernels, the image files in the
page cache). The ratios are medians over the repeats of (five-seed time / one-seed time of the
same repeat), of wall time and of the process's CPU time (all its threads), which other work on
a shared machine moves much less than wall time.

The interval overhead is the bootstrap of the five-seed cell in both matching modes (what the
run table computes for it, `uncertainty.bootstrap`; median of `repeats` after one untimed call)
as a share of the five-seed cell's time (shared).
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict
from functools import partial
from pathlib import Path
from typing import Any

from safl_bench.errors import ConfigError
from safl_bench.methods.method import Method
from safl_bench.run import timing

DEFAULT_TASK = "SAFL/BEVKITTI00-T1R1-v1"
#: version 1 of both: the figures of issue 25 were measured on them, and they are the versions
#: with shipped weights on the synthetic default (`make_method` below picks no source)
DEFAULT_METHODS = ("stable_afl@1", "bigan@1")
SEEDS = 5


def _timed_run(method: Method, task_id: str, bev_root: str, n_seeds: int, share: bool
               ) -> tuple[float, float, list[Any]]:
    """Wall and process CPU seconds of `run_grid` of one cell at `n_seeds` seeds from a scratch
    home, and its outcomes."""
    from safl_bench.run import runner

    before = os.environ.get("SAFL_HOME")
    with tempfile.TemporaryDirectory(prefix="safl-bench-seeds-") as scratch:
        os.environ["SAFL_HOME"] = scratch
        try:
            options = runner.RunOptions(results_dir=Path(scratch) / "results", bev_root=bev_root,
                                        progress=False, share_seeds=share)
            c0, t0 = time.process_time(), time.perf_counter()
            outcomes = runner.run_grid([method], [task_id], options, n_seeds=n_seeds,
                                       log=lambda message: None)
            seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
        finally:
            if before is None:
                os.environ.pop("SAFL_HOME", None)
            else:
                os.environ["SAFL_HOME"] = before
    failed = [o.message for o in outcomes if o.record is None]
    if failed:
        raise ConfigError(f"a benchmark cell of {method.name} on {task_id} failed: {failed[0]}")
    return seconds, cpu, outcomes


def _interval_seconds(outcomes: Sequence[Any], repeats: int) -> float:
    """Median seconds of the bootstrap of the cell's seeds in both matching modes."""
    from safl_bench.evaluation.uncertainty import bootstrap
    from safl_bench.results.records import MODES, seed_outcomes

    records = [o.record for o in outcomes]
    per_mode = [seed_outcomes(records, mode) for mode in MODES]
    if any(p is None for p in per_mode):
        raise ConfigError("the cell's records hold no per-query outcomes: no interval to time")

    def run() -> None:
        for seeds in per_mode:
            assert seeds is not None
            bootstrap(seeds)

    return timing.time_call(run, name="bootstrap", repeats=repeats, warmup=1, memory=False).median_s


def _ratio(runs: dict[str, list[float]], key: str) -> float:
    """Median over the repeats of runs[key] / the one-seed figure of the same kind and repeat."""
    one = runs["one_cpu_s" if key.endswith("cpu_s") else "one_s"]
    return statistics.median(s / o for s, o in zip(runs[key], one, strict=True))


def run(bev_root: str, methods: Sequence[str] | None = None, *, task_id: str = DEFAULT_TASK,
        repeats: int = 3) -> dict[str, Any]:
    """Every figure, JSON-ready."""
    from safl_bench.methods.method import make_method
    from safl_bench.tasks import spec

    if repeats < 1:
        raise ConfigError(f"--repeats must be >= 1, got {repeats}")
    task = spec(task_id)
    if len(task.seeds) < 2:
        raise ConfigError(f"task {task_id} has one seed (nothing random): no seeds to compare")
    out: dict[str, Any] = {"task": task_id, "seeds": SEEDS, "repeats": repeats, "methods": {}}
    for name in methods or DEFAULT_METHODS:
        method = make_method(name)
        _timed_run(method, task_id, bev_root, 1, True)  # warm-up
        runs: dict[str, list[float]] = {f"{k}_{c}": [] for k in ("one", "shared", "alone")
                                        for c in ("s", "cpu_s")}
        outcomes: list[Any] = []
        for _ in range(repeats):
            for label, n, share in (("one", 1, True), ("shared", SEEDS, True),
                                    ("alone", SEEDS, False)):
                seconds, cpu, got = _timed_run(method, task_id, bev_root, n, share)
                runs[f"{label}_s"].append(seconds)
                runs[f"{label}_cpu_s"].append(cpu)
                outcomes = got if label == "shared" else outcomes
        ratio = partial(_ratio, runs)

        interval_s = _interval_seconds(outcomes, repeats)
        shared = statistics.median(runs["shared_s"])
        out["methods"][name] = {
            **runs,
            "ratio_shared": ratio("shared_s"), "ratio_alone": ratio("alone_s"),
            "cpu_ratio_shared": ratio("shared_cpu_s"), "cpu_ratio_alone": ratio("alone_cpu_s"),
            "interval_s": interval_s, "interval_share": interval_s / shared,
        }
    out["environment"] = asdict(timing.environment())
    return out


def format_results(r: dict[str, Any]) -> str:
    """The figures as a few lines of text."""
    lines = [f"{r['task']}: wall time of the cell at {r['seeds']} seeds / at one seed, each run "
             f"from no records and no cached views (median over {r['repeats']} repeats)"]
    for name, m in r["methods"].items():
        one, shared, alone = (statistics.median(m[k]) for k in ("one_s", "shared_s", "alone_s"))
        lines.append(
            f"  {name}: one seed {one:.1f} s; {r['seeds']} seeds sharing the cell's timing and "
            f"database {shared:.1f} s -> {m['ratio_shared']:.2f}x (target <= 2.5x); each seed "
            f"alone {alone:.1f} s -> {m['ratio_alone']:.2f}x")
        lines.append(
            f"  {name}: process CPU time (less moved by other work on the machine): sharing "
            f"{m['cpu_ratio_shared']:.2f}x, each seed alone {m['cpu_ratio_alone']:.2f}x")
        lines.append(
            f"  {name}: intervals of the {r['seeds']}-seed cell (bootstrap, both matching modes) "
            f"{m['interval_s']:.2f} s = {100 * m['interval_share']:.1f} % of the cell "
            "(target <= 5 %)")
    env = r.get("environment", {})
    if env.get("load_avg_1m") is not None:
        lines.append(f"load average at the end: {env['load_avg_1m']:.2f} on "
                     f"{env.get('usable_cpus')} usable CPUs")
    return "\n".join(lines)
