"""pytest-benchmark figures for the matcher (skipped by default; run with
``pytest tests/bench_matching.py --benchmark-enable -p no:cacheprovider``).
The full KITTI-00-sized figures with the loop ratio: ``python -m safl_bench.matching_bench``."""

from __future__ import annotations

import numpy as np
import pytest

from safl_bench import distance, matching


@pytest.fixture(scope="module")
def descriptors() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    n = 4541
    return (rng.standard_normal((n, 1024), dtype=np.float32),
            rng.standard_normal((n, 1024), dtype=np.float32))


def test_bench_descriptors_to_matches(benchmark, descriptors) -> None:  # type: ignore[no-untyped-def]
    q, db = descriptors
    matching.seqslam(np.ones((12, 12)))  # kernels compiled outside the clock
    res = benchmark.pedantic(lambda: matching.seqslam(distance.sqeuclidean(q, db)),
                             rounds=3, warmup_rounds=1)
    assert res.index.shape == (4541,)


def test_bench_matcher_only(benchmark, descriptors) -> None:  # type: ignore[no-untyped-def]
    D = distance.sqeuclidean(*descriptors)
    res = benchmark.pedantic(lambda: matching.seqslam(D), rounds=3, warmup_rounds=1)
    assert res.index.shape == (4541,)
