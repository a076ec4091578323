"""Benchmarks of the classic descriptors (pytest-benchmark); not part of the default run.

Run:  pytest tests/bench_classics.py -o addopts="" -s
Prints ms per scan to describe (Scan Context target <= 2 ms, M2DP <= 5 ms) and the time of a
4541 x 4541 Scan Context difference matrix (target <= 30 s), on synthetic local maps
(tests/classic_scenes.py) of ~75k-150k points.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from classic_scenes import rotate_z, scene
from threadpoolctl import threadpool_limits

from baselines.m2dp import m2dp
from baselines.scan_context import distance_matrix, scan_context

N_MATRIX = 4541


@pytest.fixture(scope="module")
def clouds() -> dict[str, list[np.ndarray]]:
    small = [scene(seed) for seed in range(4)]
    large = [np.concatenate([small[i], rotate_z(small[(i + 1) % 4], 0.5)]) for i in range(4)]
    return {"~75k": small, "~150k": large}


def _per_scan(benchmark, fn, clouds: list[np.ndarray], label: str, target_ms: float) -> None:  # type: ignore[no-untyped-def]
    for c in clouds:
        fn(c)  # compile / warm up
    state = {"i": 0}

    def one() -> None:
        fn(clouds[state["i"] % len(clouds)])
        state["i"] += 1

    benchmark.pedantic(one, rounds=40, iterations=1, warmup_rounds=2)
    median_ms = benchmark.stats.stats.median * 1e3
    points = int(np.mean([len(c) for c in clouds]))
    print(f"\n{label}: {median_ms:.2f} ms per scan (median, {points} points; target <= {target_ms} ms)")


@pytest.mark.parametrize("size", ["~75k", "~150k"])
def test_scan_context_describe(benchmark, clouds, size) -> None:  # type: ignore[no-untyped-def]
    _per_scan(benchmark, scan_context, clouds[size], f"scan_context describe {size}", 2.0)


@pytest.mark.parametrize("size", ["~75k", "~150k"])
def test_m2dp_describe(benchmark, clouds, size) -> None:  # type: ignore[no-untyped-def]
    with threadpool_limits(limits=1, user_api="blas"):  # as M2DP.describe does
        _per_scan(benchmark, m2dp, clouds[size], f"m2dp describe {size}", 5.0)


def test_scan_context_matrix(benchmark, clouds) -> None:  # type: ignore[no-untyped-def]
    """4541 x 4541 distances (with shifts): descriptors of a few scenes under random headings
    and per-bin noise, so that they look like a sequence's (columns mostly non-empty)."""
    rng = np.random.default_rng(0)
    base = np.stack([scan_context(c) for c in clouds["~75k"]])
    pick = rng.integers(0, len(base), N_MATRIX)
    desc = np.stack([np.roll(base[i], int(rng.integers(60)), axis=1) for i in pick])
    desc = desc * rng.uniform(0.8, 1.2, desc.shape).astype(np.float32)
    desc[rng.random(desc.shape) < 0.1] = 0
    distance_matrix(desc[:8], desc[:8])  # compile
    start = time.perf_counter()
    dist = benchmark.pedantic(distance_matrix, args=(desc, desc), rounds=1, iterations=1)
    seconds = time.perf_counter() - start
    assert dist.shape == (N_MATRIX, N_MATRIX)
    print(f"\nscan_context {N_MATRIX} x {N_MATRIX} difference matrix: {seconds:.1f} s (target <= 30 s)")
