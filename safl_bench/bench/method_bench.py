"""Benchmark of descriptor methods on the benchmark's own views (the paper's Table III).

For each method: milliseconds per frame at batch 1 (the robot's case), throughput in batches,
and for methods with their own distance the time of a KITTI-00-sized difference matrix
(4541 x 4541 descriptors, drawn from the real ones with replacement). Views are those of a
clean task (by default `SAFL/Synth00-T0R0-v6`, generated and cached on first use), so every
method is timed on the input it declares (top-view maps or local-map points), resampled to its
`input_size` as the runner does. A method whose cost depends on the view size and that is
published for one size (class attribute `bench_view_size`, e.g. BEVPlace's 151 x 151 images) is
timed on the views resampled to that size (timing does not depend on the content); the result
says so (`views`). Slow methods are timed batched on a prefix of the views of about
`batched_budget_s` seconds' work (estimated from the batch-1 figure), at least one batch.

A method may name a former distance (class attribute `bench_reference_distance`, a (name,
function) pair; SAD: torch.cdist(p=1)), timed on the same matrix with the speed-up and whether
the results are bitwise equal, and a bound (`bench_distance_bound(nq, ndb, dim)`, returning
`bound_s` with how it was reached; SAD: its absolute differences at the CPU's vector rate
measured in the same run), printed with the matrix time's ratio to it.

    safl-bench bench methods --method stable_afl --method scan_context
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from safl_bench.methods.method import (
    Method,
    list_methods,
    make_method,
    method_class,
    method_input,
    resolve_method,
    shipped_weights_path,
)
from safl_bench.run import timing

DEFAULT_TASK = "SAFL/Synth00-T0R0-v6"
MATRIX_N = 4541
BATCHED_BUDGET_S = 10.0


def _own_distance(method: Method) -> bool:
    return type(method).distance is not Method.distance


def timing_views(method: Method, views: Any) -> tuple[Any, str | None]:
    """The views `method` is timed on, and a note when they were resampled for it."""
    views = method_input(method, views)
    size = getattr(type(method), "bench_view_size", None)
    if method.input_kind != "topview" or size is None:
        return views, None
    arr = np.asarray(views)
    if arr.shape[1:] == (size, size):
        return arr, None
    from safl_bench.views.resample import fit_input

    note = f"{arr.shape[1]}x{arr.shape[2]} views resampled to {size}x{size} for timing"
    return fit_input(arr, size), note


def bench_method(
    method: Method,
    views: Any,
    *,
    frames: int = 50,
    batch_size: int = 64,
    repeats: int = 5,
    matrix_n: int | None = MATRIX_N,
    batched_budget_s: float | None = BATCHED_BUDGET_S,
) -> dict[str, Any]:
    """All the figures of one method, JSON-ready."""
    views, note = timing_views(method, views)
    batch1 = timing.time_describe(method, views, batch_size=1, frames=frames, repeats=repeats)
    batched_frames = None
    if batched_budget_s is not None and batch1.median_s > 0:
        per_frame_s = batch1.median_s / max(1, batch1.n_items)
        affordable = max(batch_size, int(batched_budget_s / per_frame_s))
        batched_frames = affordable if affordable < len(views) else None
    batched = timing.time_describe(method, views, batch_size=batch_size, frames=batched_frames,
                                   repeats=max(1, repeats // 2))
    out: dict[str, Any] = {
        "method": method.name,
        "version": method.version,
        "weights": (method.weights_info or {}).get("source"),
        "input": method.input_kind,
        "batch1": batch1.to_dict(),
        "batched": batched.to_dict(),
    }
    if note:
        out["views"] = note
    if matrix_n:
        desc = np.asarray(method.describe(views[:batched.n_items]))
        pick = np.random.default_rng(0).integers(0, len(desc), matrix_n)
        big = np.ascontiguousarray(desc[pick])
        method.distance(big[:8], big[:8])  # compile / warm up
        mat = timing.time_call(lambda: method.distance(big, big), name="difference matrix",
                               repeats=1, warmup=0, n_items=matrix_n)
        out["matrix"] = {"n": matrix_n, "own_distance": _own_distance(method), **mat.to_dict()}
        reference = getattr(type(method), "bench_reference_distance", None)
        if reference is not None:
            out["matrix"]["reference"] = _reference_matrix(method, reference, big, mat.median_s)
        bound = getattr(type(method), "bench_distance_bound", None)
        if bound is not None:
            out["matrix"]["bound"] = _bound_rounds(method, bound, big, rounds=max(1, min(3, repeats)))
    return out


def _reference_matrix(method: Method, reference: Any, big: np.ndarray, own_s: float) -> dict[str, Any]:
    """The method's former (reference) distance on the same matrix, timed in the same run, and
    how far the method's own result is from it."""
    name, fn = reference
    own = np.asarray(method.distance(big, big))
    ref_timing = timing.time_call(lambda: fn(big, big), name=f"difference matrix ({name})",
                                  repeats=1, warmup=0, n_items=len(big))
    ref = np.asarray(fn(big, big))
    return {"name": name, "median_s": ref_timing.median_s, "speedup": ref_timing.median_s / own_s,
            "bitwise_equal": bool(np.array_equal(own, ref)),
            "max_abs_diff": float(np.abs(own.astype(np.float64) - ref).max()) if own.size else 0.0}


def _bound_rounds(method: Method, bound: Any, big: np.ndarray, rounds: int) -> dict[str, Any]:
    """The matrix against its bound in `rounds` rounds, each the bound's rate measured just
    before the matrix is timed (wall and CPU time), so other work on a shared machine slows
    both alike; the medians of the per-round figures and ratios."""
    per_round = []
    for _ in range(rounds):
        figures = bound(len(big), len(big), big.shape[1])
        t0, c0 = time.perf_counter(), time.process_time()
        method.distance(big, big)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        per_round.append({**figures, "matrix_s": wall, "matrix_cpu_s": cpu,
                          "ratio": wall / figures["bound_s"], "ratio_cpu": cpu / figures["bound_cpu_s"]})
    out: dict[str, Any] = {k: statistics.median(r[k] for r in per_round) for k in per_round[0]}
    out["rounds"] = rounds
    return out


def run(
    methods: Sequence[str] | None = None,
    *,
    task_id: str = DEFAULT_TASK,
    frames: int = 50,
    repeats: int = 5,
    matrix_n: int | None = MATRIX_N,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Figures for each method (default: every registered version of every method, `name@V`
    where a name has several), with the shipped weights where a method has them and its
    untrained networks where it has none (timing does not depend on the weights' values)."""
    from safl_bench.tasks.task import make

    names = list(methods) if methods else default_methods()
    for name in names:
        method_class(name)  # an unknown name or version fails before any work
    task = make(task_id, progress=progress)
    results = []
    for name in names:
        cls = method_class(resolve_method(name))  # a bare name: the version `run` runs
        untrained = cls.trainable and shipped_weights_path(cls) is None
        method = make_method(f"{cls.name}@{cls.version}", weights="untrained" if untrained else None)
        views = task.database(method.input_kind)
        results.append(bench_method(method, views, frames=frames, repeats=repeats, matrix_n=matrix_n))
    return results


def default_methods() -> list[str]:
    """Every registered version of every method, as a command selects it: `name@V` where the
    name has several versions, else the bare name."""
    infos = list_methods(all_versions=True)
    names = [i.name for i in infos]
    return [f"{i.name}@{i.version}" if names.count(i.name) > 1 else i.name for i in infos]


def format_results(results: Sequence[dict[str, Any]]) -> str:
    """A plain-text table: ms/frame at batch 1, frames/s batched, matrix seconds (a method
    timed at two versions is labelled `name@V`)."""
    names = [r["method"] for r in results]

    def who(r: dict[str, Any]) -> str:
        return f"{r['method']}@{r.get('version')}" if names.count(r["method"]) > 1 else str(r["method"])

    lines = [f"{'method':14s} {'input':8s} {'ms/frame (b=1)':>15s} {'frames/s (batched)':>19s} "
             f"{'4541² matrix s':>15s}"]
    for r in results:
        matrix = r.get("matrix")
        mat = f"{matrix['median_s']:.2f}" if matrix else "-"
        lines.append(f"{who(r):14s} {r['input']:8s} {r['batch1']['per_item_ms']:15.2f} "
                     f"{r['batched']['extra']['frames_per_s']:19.0f} {mat:>15s}")
    for r in results:
        ref = (r.get("matrix") or {}).get("reference")
        if ref:
            lines.append(f"({who(r)}: matrix {r['matrix']['median_s']:.2f} s against {ref['median_s']:.2f} s "
                         f"with {ref['name']} in the same run, {ref['speedup']:.1f}x; "
                         + ("bitwise equal" if ref["bitwise_equal"] else f"max abs diff {ref['max_abs_diff']:.1e}")
                         + ")")
        bound = (r.get("matrix") or {}).get("bound")
        if bound:
            lines.append(f"({who(r)}: matrix {bound['matrix_s']:.2f} s against the bound "
                         f"{bound['bound_s']:.2f} s, {bound['absdiffs'] / 1e9:.1f} G absolute differences at "
                         f"{bound['rate_per_s'] / 1e9:.1f} G/s, this CPU's vector rate measured just before: "
                         f"{bound['ratio']:.2f}x the bound; by CPU time {bound['matrix_cpu_s']:.2f} s against "
                         f"{bound['bound_cpu_s']:.2f} s, {bound['ratio_cpu']:.2f}x; medians of "
                         f"{bound['rounds']} rounds)")
    for r in results:
        if r.get("views"):
            lines.append(f"({who(r)}: {r['views']}; batched: {r['batched']['n_items']} frames)")
    env = results[0]["batch1"]["env"] if results else None
    if env:
        lines.append(f"({env['cpu_model']}, {env['usable_cpus']} CPUs, torch threads "
                     f"{env['torch_threads']}, load avg {env['load_avg_1m']})")
    return "\n".join(lines)
