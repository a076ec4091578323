"""Scan Context: descriptor binning, rotation invariance, shift/heading, vectorised == per-pair."""

from __future__ import annotations

import numpy as np
import pytest
from classic_scenes import SENSOR_HEIGHT, rotate_z, scene

from baselines.scan_context import (
    ScanContext,
    align,
    distance_matrix,
    ring_key,
    ring_key_candidates,
    scan_context,
    shift_to_heading,
)
from safl_bench.errors import DataError

SECTOR = 2 * np.pi / 60


def reference_distance(q: np.ndarray, d: np.ndarray) -> tuple[float, int]:
    """A plain per-pair reference after the original C++ (distDirectSC over every shift): for
    each shift, the mean cosine over the columns non-zero in both; distance 1 - the best."""
    best_sim, best_shift = -np.inf, 0
    num_sectors = q.shape[1]
    qq = q.astype(np.float64)
    for s in range(num_sectors):
        rolled = d[:, (np.arange(num_sectors) - s) % num_sectors].astype(np.float64)
        na, nb = np.linalg.norm(qq, axis=0), np.linalg.norm(rolled, axis=0)
        both = (na > 0) & (nb > 0)
        cosines = (qq * rolled).sum(axis=0)[both] / (na * nb)[both]
        sim = float(cosines.mean()) if both.any() else 0.0
        if sim > best_sim:
            best_sim, best_shift = sim, s
    return max(0.0, 1.0 - best_sim), best_shift


def _wrap(angle: float) -> float:
    return (angle + np.pi) % (2 * np.pi) - np.pi


@pytest.fixture(scope="module")
def scenes() -> list[np.ndarray]:
    return [scene(seed) for seed in range(6)]


def test_binning_matches_arctan2_reference(scenes: list[np.ndarray]) -> None:
    rng = np.random.default_rng(3)
    pts = np.concatenate([scenes[0], rng.uniform(-100, 100, (20000, 3)).astype(np.float32)])
    p = pts.astype(np.float64)
    r = np.hypot(p[:, 0], p[:, 1])
    ang = np.arctan2(p[:, 1], p[:, 0]) % (2 * np.pi)
    inside = r <= 80.0
    ring = np.minimum((r / 4.0).astype(int), 19)
    sector = np.minimum((ang / SECTOR).astype(int), 59)
    ref = np.zeros(1200)
    np.maximum.at(ref, (ring * 60 + sector)[inside], p[inside, 2] + SENSOR_HEIGHT)
    got = scan_context(pts, sensor_height=SENSOR_HEIGHT)
    assert got.shape == (20, 60) and got.dtype == np.float32
    np.testing.assert_allclose(got, ref.reshape(20, 60), atol=1e-5)
    assert got.min() >= 0.0


def test_empty_cloud_and_bad_shape() -> None:
    assert not scan_context(np.zeros((0, 3), np.float32)).any()
    with pytest.raises(DataError):
        scan_context(np.zeros((5, 2), np.float32))


@pytest.mark.parametrize("k", [1, 7, 30, 59])
def test_rotation_by_whole_sectors_is_exact(scenes: list[np.ndarray], k: int) -> None:
    base = scan_context(scenes[0])
    rotated = scan_context(rotate_z(scenes[0], k * SECTOR))
    dist, shift = align(rotated, base)
    assert dist < 1e-6
    assert shift == k
    assert np.isclose(shift_to_heading(shift), _wrap(-k * SECTOR))


@pytest.mark.parametrize("angle", [0.3, -1.0, 2.5])
def test_rotation_by_other_angles_is_near_zero(scenes: list[np.ndarray], angle: float) -> None:
    base = scan_context(scenes[1])
    rotated = scan_context(rotate_z(scenes[1], angle))
    dist, shift = align(rotated, base)
    others = [align(rotated, scan_context(s))[0] for s in scenes[2:]]
    assert dist < 0.15 and dist < 0.5 * min(others)
    expected = angle / SECTOR
    circular_error = abs((shift - expected + 30) % 60 - 30)
    assert circular_error <= 1.0
    assert abs(_wrap(float(shift_to_heading(shift)) + angle)) <= SECTOR + 1e-9


def _random_descriptors(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = rng.random((n, 20, 60)).astype(np.float32) * 5
    d[rng.random(d.shape) < 0.4] = 0
    # some descriptors with whole empty columns (the count then depends on the shift)
    for i in range(0, n, 3):
        d[i][:, rng.random(60) < 0.3] = 0
    d[n // 2] = 0  # an all-empty descriptor
    return d


def test_vectorised_matrix_equals_per_pair_loop() -> None:
    q = _random_descriptors(7, 0)
    d = _random_descriptors(9, 1)
    d[4] = np.roll(q[2], -11, axis=1)  # q[2] = roll(d[4], 11)
    dist, shift = distance_matrix(q, d, return_shift=True, max_bytes=3 * 1100 * 9)  # several chunks
    assert dist.shape == (7, 9) and dist.dtype == np.float32
    for i in range(7):
        for j in range(9):
            ref_dist, ref_shift = reference_distance(q[i], d[j])
            assert abs(dist[i, j] - ref_dist) < 1e-5, (i, j)
            if abs(ref_dist - 1.0) > 1e-9:  # undefined shift when nothing overlaps
                assert shift[i, j] == ref_shift, (i, j)
            assert align(q[i], d[j])[0] == pytest.approx(ref_dist, abs=1e-9)
    assert dist[2, 4] < 1e-6 and shift[2, 4] == 11


def test_ring_key_candidates_contain_the_true_match(scenes: list[np.ndarray]) -> None:
    db = np.stack([scan_context(s) for s in scenes])
    queries = np.stack([scan_context(rotate_z(s, 1.234)) for s in scenes])
    assert ring_key(db).shape == (6, 20)
    cand = ring_key_candidates(queries, db, k=2)
    assert cand.shape == (6, 2)
    assert all(i in cand[i] for i in range(6))
    assert ring_key_candidates(queries, db, k=50).shape == (6, 6)


def test_method_plugin(scenes: list[np.ndarray]) -> None:
    method = ScanContext()
    assert method.input_kind == "points" and method.name == "scan_context"
    desc = method.describe(scenes[:3])
    assert desc.shape == (3, 1200) and desc.dtype == np.float32
    rotated = method.describe([rotate_z(scenes[0], 7 * SECTOR)])
    dist, shift = method.distance_and_shift(rotated, desc)
    assert dist.shape == (1, 3) and int(np.argmin(dist[0])) == 0 and shift[0, 0] == 7
    np.testing.assert_allclose(method.heading(shift[:, :1]), -7 * SECTOR)
    assert method.candidates(rotated, desc, k=1)[0, 0] == 0
    with pytest.raises(DataError):
        method.distance(desc[:, :100], desc)


def test_check_method() -> None:
    check = pytest.importorskip("safl_bench.check")
    check.check_method(ScanContext())
