"""SAD: SeqSLAM's patch-normalised thumbnails and sum of absolute differences."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from baselines.sad import (
    SAD,
    absdiff_rate,
    pack_database,
    patch_normalise,
    sad_matrix,
    sad_matrix_cdist,
)
from safl_bench.check import check_method, sample_views
from safl_bench.errors import ConfigError, DataError


def test_conforms():
    check_method(SAD())
    check_method(SAD(size=16, patch=4, normalisation="zscore"))


def test_descriptor_is_downsampled_and_patch_normalised():
    maps = sample_views("topview", n=5)
    d = SAD().describe(maps)
    assert d.shape == (5, 32 * 32) and d.dtype == np.float32
    img = d[0].reshape(32, 32)
    # the 2x2 block mean of the 64x64 map, then per 8x8 patch: zero mean, unit range
    small = maps[0].reshape(32, 2, 32, 2).mean(axis=(1, 3))
    for r in range(0, 32, 8):
        for c in range(0, 32, 8):
            patch, src = img[r : r + 8, c : c + 8], small[r : r + 8, c : c + 8]
            assert abs(patch.mean()) < 1e-5
            assert patch.max() - patch.min() == pytest.approx(1.0, abs=1e-5)
            np.testing.assert_allclose(patch, (src - src.mean()) / (src.max() - src.min()), atol=1e-5)


def test_constant_patches_become_zero():
    out = patch_normalise(np.full((1, 16, 16), 0.7, np.float32), 8)
    assert np.array_equal(out, np.zeros_like(out))


def test_distance_is_mean_absolute_difference():
    rng = np.random.default_rng(1)
    q, db = rng.normal(size=(7, 64)).astype(np.float32), rng.normal(size=(11, 64)).astype(np.float32)
    expected = np.abs(q[:, None, :] - db[None]).mean(axis=2)
    np.testing.assert_allclose(SAD().distance(q, db), expected, rtol=1e-5)
    np.testing.assert_allclose(SAD(chunk_rows=3).distance(q, db), expected, rtol=1e-5)


def _plain_sad(q: np.ndarray, db: np.ndarray) -> np.ndarray:
    """The plain reference: float32 sums, one term after another, then / D."""
    acc = np.zeros((len(q), len(db)), np.float32)
    for x in range(q.shape[1]):
        acc += np.abs(q[:, x, None] - db[None, :, x])
    return acc / np.float32(max(q.shape[1], 1))


@pytest.mark.parametrize(("nq", "ndb", "dim"), [(1, 1, 1), (7, 11, 64), (33, 129, 37), (65, 300, 1024),
                                                 (3, 257, 5), (0, 4, 8), (4, 0, 8)])
def test_fast_distance_is_bitwise_the_plain_sum_and_cdist(nq, ndb, dim):
    """The kernel (tiles of 32 x 128, odd sizes and partial tiles included) gives exactly the
    plain sequential float32 sum and exactly torch.cdist(p=1), the former implementation."""
    rng = np.random.default_rng(nq * 1000 + ndb + dim)
    q = rng.random((nq, dim), dtype=np.float32) - 0.5
    db = rng.random((ndb, dim), dtype=np.float32) - 0.5
    fast = sad_matrix(q, db)
    assert fast.dtype == np.float32 and fast.shape == (nq, ndb)
    assert np.array_equal(fast, _plain_sad(q, db))
    assert np.array_equal(fast, sad_matrix_cdist(q, db))
    assert np.array_equal(SAD(chunk_rows=5).distance(q, db), fast)
    if nq and ndb:
        cdist = torch.cdist(torch.from_numpy(q), torch.from_numpy(db), p=1).numpy() / np.float32(dim)
        assert np.array_equal(fast, cdist)


def test_database_panels_hold_each_tile_transposed_and_zero_padded():
    db = np.arange(130 * 3, dtype=np.float32).reshape(130, 3)
    panels = pack_database(db)
    assert panels.shape == (2, 3, 128) and panels.flags.c_contiguous
    assert np.array_equal(panels[0], db[:128].T)
    assert np.array_equal(panels[1, :, :2], db[128:].T) and not panels[1, :, 2:].any()


def test_vector_rate_probe_reports_wall_and_cpu_rates():
    rate = absdiff_rate(seconds=0.03, dim=16)
    assert rate["rate_per_s"] > 0 and rate["rate_per_cpu_s"] > 0


def test_fast_distance_on_descriptors_matches_the_plain_sum():
    maps = np.random.default_rng(3).random((9, 64, 64)).astype(np.float32)
    d = SAD().describe(maps)
    assert np.array_equal(SAD().distance(d[:4], d), _plain_sad(d[:4], d))
    assert np.array_equal(SAD().distance(d[::2], d[::-1]), _plain_sad(d[::2], d[::-1]))  # strided views


def test_non_multiple_sizes_use_area_resizing():
    maps = np.random.default_rng(0).random((3, 50, 50)).astype(np.float32)
    assert SAD(size=32).describe(maps).shape == (3, 1024)


def test_bad_inputs_and_settings_are_reported():
    with pytest.raises(DataError, match="one map"):
        SAD().describe(np.zeros((64, 64), np.float32))
    with pytest.raises(DataError, match="NaN"):
        SAD().describe(np.full((1, 64, 64), np.nan, np.float32))
    with pytest.raises(DataError, match=r"\[0, 1\]"):
        SAD().describe(np.full((1, 64, 64), 2.0, np.float32))
    with pytest.raises(DataError, match="smaller than size"):
        SAD(size=32).describe(np.zeros((1, 16, 16), np.float32))
    with pytest.raises(ConfigError, match="patch must divide"):
        SAD(size=32, patch=5).describe(np.zeros((1, 64, 64), np.float32))
    with pytest.raises(ConfigError, match="normalisation"):
        SAD(normalisation="l2").describe(np.zeros((1, 64, 64), np.float32))


def test_speed_per_frame(benchmark):
    """Target: at most 0.2 ms per frame at batch 1 (run with --benchmark-only)."""
    maps = sample_views("topview", n=1)
    method = SAD()
    benchmark(method.describe, maps)
    assert benchmark.stats.stats.median < 0.2e-3
