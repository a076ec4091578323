"""pytest-benchmark figures for the viewpoint move of an image source's noisy queries (skipped by
default; run with ``pytest tests/bench_resample.py --benchmark-enable -p no:cacheprovider``):
the stacked kernel of `safl_bench.views.resample.move_viewpoint` against scipy's
`affine_transform` image by image, on one noisy query set of real KITTI 00's size (1136 images of
151 x 151, uint8)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import affine_transform

from safl_bench.views.resample import _affine, move_viewpoint


@pytest.fixture(scope="module")
def queries() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    n, size = 1136, 151
    images = rng.integers(0, 256, (n, size, size), dtype=np.uint8)
    offsets = np.c_[rng.uniform(-20.0, 20.0, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    return images, offsets


def _scipy_per_image(images: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    out = np.empty_like(images)
    for i in range(len(images)):
        matrix, shift = _affine(images.shape[1], offsets[i], 0.4)
        affine_transform(images[i], matrix, offset=shift, output=out[i], order=0, mode="constant",
                         cval=0)
    return out


def test_bench_move_viewpoint_stacked_kernel(benchmark, queries) -> None:  # type: ignore[no-untyped-def]
    images, offsets = queries
    move_viewpoint(images[:2], offsets[:2], 0.4)  # kernel compiled outside the clock
    out = benchmark.pedantic(lambda: move_viewpoint(images, offsets, 0.4), rounds=5,
                             warmup_rounds=1)
    assert np.array_equal(out[:16], _scipy_per_image(images[:16], offsets[:16]))


def test_bench_move_viewpoint_scipy_per_image(benchmark, queries) -> None:  # type: ignore[no-untyped-def]
    images, offsets = queries
    out = benchmark.pedantic(lambda: _scipy_per_image(images, offsets), rounds=5, warmup_rounds=1)
    assert out.shape == images.shape
