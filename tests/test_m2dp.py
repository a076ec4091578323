"""M2DP: shapes, determinism, exact binning, rotation invariance about the vertical axis."""

from __future__ import annotations

import numpy as np
import pytest
from classic_scenes import rotate_z, scene

from baselines.m2dp import M2DP, m2dp, pca_align, projection_planes, signature_matrix, subsample
from safl_bench.errors import ConfigError, DataError


@pytest.fixture(scope="module")
def scenes() -> list[np.ndarray]:
    return [scene(seed) for seed in range(5)]


def _sq(a: np.ndarray, b: np.ndarray) -> float:
    return float(((a.astype(np.float64) - b) ** 2).sum())


def test_signature_matrix_matches_arctan2_reference(scenes: list[np.ndarray]) -> None:
    pts = scenes[0][::25]
    a = signature_matrix(pts)
    assert a.shape == (64, 128)
    np.testing.assert_allclose(a.sum(axis=1), 1.0)
    data = pca_align(pts)
    max_rho = np.sqrt((data**2).sum(axis=1).max())
    px, py = projection_planes(4, 16)
    ref = np.zeros((64, 128))
    for k in range(64):
        u, v = data @ px[k], data @ py[k]
        sector = np.minimum(((np.arctan2(v, u) + np.pi) / (np.pi / 8)).astype(int), 15)
        ring = np.minimum((8 * np.sqrt(np.hypot(u, v) / max_rho)).astype(int), 7)
        np.add.at(ref[k], ring * 16 + sector, 1.0)
    np.testing.assert_allclose(a, ref / len(pts), atol=1e-12)


def test_planes_are_orthonormal() -> None:
    px, py = projection_planes(4, 16)
    assert px.shape == py.shape == (64, 3)
    np.testing.assert_allclose(np.linalg.norm(px, axis=1), 1.0)
    np.testing.assert_allclose(np.linalg.norm(py, axis=1), 1.0)
    np.testing.assert_allclose((px * py).sum(axis=1), 0.0, atol=1e-12)


def test_shape_and_determinism(scenes: list[np.ndarray]) -> None:
    d1 = m2dp(scenes[0])
    d2 = m2dp(scenes[0].copy())
    assert d1.shape == (192,) and d1.dtype == np.float32
    np.testing.assert_array_equal(d1, d2)
    assert np.isclose(np.linalg.norm(d1[:64]), 1.0, atol=1e-5)
    assert np.isclose(np.linalg.norm(d1[64:]), 1.0, atol=1e-5)
    assert d1[:64].sum() + d1[64:].sum() >= 0
    assert not m2dp(np.zeros((0, 3), np.float32)).any()


@pytest.mark.parametrize("angle", [0.3, np.pi / 2, -2.0, 3.0])
def test_invariant_to_rotation_about_z(scenes: list[np.ndarray], angle: float) -> None:
    base = [m2dp(s) for s in scenes]
    rotated = m2dp(rotate_z(scenes[0], angle))
    own = _sq(rotated, base[0])
    others = min(_sq(rotated, b) for b in base[1:])
    assert own < 1e-4
    assert own < 0.01 * others


def test_invariant_with_translation_and_shuffle_of_the_same_points(scenes: list[np.ndarray]) -> None:
    pts = scenes[2][::4]
    moved = rotate_z(pts, 1.1) + np.float32([3.0, -2.0, 0.5])
    assert _sq(m2dp(moved, max_points=None), m2dp(pts, max_points=None)) < 1e-4


def test_subsample_is_deterministic_and_close(scenes: list[np.ndarray]) -> None:
    pts = scenes[1]
    a = subsample(pts, 5000)
    np.testing.assert_array_equal(a, subsample(pts, 5000))
    assert len(a) == 5000 and subsample(pts, None) is pts
    full = m2dp(pts, max_points=None)
    assert _sq(m2dp(pts, max_points=5000), full) < 0.1 * _sq(full, m2dp(scenes[3], max_points=None))


def test_method_plugin(scenes: list[np.ndarray]) -> None:
    method = M2DP()
    assert method.input_kind == "points" and method.name == "m2dp"
    desc = method.describe(scenes[:3])
    assert desc.shape == (3, 192) and desc.dtype == np.float32
    query = method.describe([rotate_z(scenes[1], 0.7)])
    assert int(np.argmin(method.distance(query, desc)[0])) == 1
    with pytest.raises(ConfigError):
        M2DP(num_sectors=10).describe(scenes[:1])
    with pytest.raises(DataError):
        method.describe([np.zeros((4, 2), np.float32)])


def test_check_method() -> None:
    check = pytest.importorskip("safl_bench.check")
    check.check_method(M2DP())


def test_signature_is_the_top_singular_pair(scenes: list[np.ndarray]) -> None:
    pts = scenes[4]
    u, _, vt = np.linalg.svd(signature_matrix(subsample(pts, 8192)))
    ref = np.concatenate([u[:, 0], vt[0]])
    ref *= np.sign(ref.sum())
    np.testing.assert_allclose(m2dp(pts, max_points=8192), ref, atol=1e-6)
