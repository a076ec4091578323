"""Sliding local maps: window and radius, the hit table, determinism, both backends agreeing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from safl_bench.localmap import HitTable, keys_to_centres, make_local_map, voxel_keys
from safl_bench.mapconfig import MapConfig
from safl_bench.sources.kitti import open_sequence
from safl_bench.topview import encode, pose_viewpoint, render

BACKENDS = ["voxel", "octomap"]


def _pose(x: float = 0.0, y: float = 0.0) -> np.ndarray:
    pose = np.eye(4)
    pose[:2, 3] = x, y
    return pose


def _ground(rng: np.random.Generator, n: int = 3000) -> np.ndarray:
    pts = np.zeros((n, 4), np.float32)
    pts[:, :2] = rng.uniform(-20, 20, (n, 2))
    pts[:, 2] = -1.73
    return pts


def test_keys_round_trip() -> None:
    pts = np.array([[0.1, -0.1, 3.9], [-100.26, 52.0, -7.3]])
    centres = keys_to_centres(voxel_keys(pts, 0.5), 0.5)
    np.testing.assert_allclose(centres, [[0.25, -0.25, 3.75], [-100.25, 52.25, -7.25]])
    assert np.all(np.abs(centres - pts) <= 0.25 + 1e-9)


def test_hit_table_matches_brute_force() -> None:
    rng = np.random.default_rng(0)
    table = HitTable(capacity=64)  # tiny: forces growth and compaction
    window: list[np.ndarray] = []
    for sid in range(30):
        keys = rng.integers(0, 400, size=rng.integers(1, 200)).astype(np.int64) + sid * 20
        distinct = table.add(keys, sid)
        np.testing.assert_array_equal(np.sort(distinct), np.unique(keys))
        window.append(distinct)
        if len(window) > 4:
            table.remove(window.pop(0))
    expect, counts = np.unique(np.concatenate(window), return_counts=True)
    live = table.keys[(table.keys != -1) & (table.hits > 0)]
    np.testing.assert_array_equal(np.sort(live), expect)
    order = np.argsort(table.keys)
    got = dict(zip(table.keys[order].tolist(), table.hits[order].tolist(), strict=True))
    assert all(got[k] == c for k, c in zip(expect.tolist(), counts.tolist(), strict=True))


@pytest.mark.parametrize("backend", BACKENDS)
def test_window_forgets_old_scans(backend: str) -> None:
    rng = np.random.default_rng(1)
    cfg = MapConfig(backend=backend, window=3)
    local = make_local_map(cfg)
    box = np.array([[5.1, 5.1, 0.1, 0.0], [5.1, 5.6, 0.1, 0.0]], np.float32)
    local.insert(np.concatenate([_ground(rng), box]), _pose())
    assert np.any(np.all(np.isclose(local.occupied(), [5.25, 5.25, 0.25]), axis=1))
    for _ in range(3):
        local.insert(_ground(rng), _pose())
    occ = local.occupied()
    assert not np.any(occ[:, 2] > 0)  # the box's scan left the window
    assert len(occ) > 100  # the ground is still there


@pytest.mark.parametrize("backend", BACKENDS)
def test_radius_drops_far_voxels(backend: str) -> None:
    rng = np.random.default_rng(2)
    cfg = MapConfig(backend=backend, window=5, radius_m=15.0)
    local = make_local_map(cfg)
    for x in range(5):
        local.insert(_ground(rng), _pose(x * 5.0))
    occ = local.occupied()
    assert np.hypot(occ[:, 0] - 20.0, occ[:, 1]).max() <= 15.0
    assert occ[:, 0].min() < 6.0  # old scans still contribute near the robot


@pytest.mark.parametrize("backend", BACKENDS)
def test_deterministic(backend: str, kitti_root: Path) -> None:
    seq = open_sequence(kitti_root, "00")
    runs = []
    for _ in range(2):
        local = make_local_map(MapConfig(backend=backend, window=2))
        for i in range(3):
            local.insert(seq.scan(i), seq.poses[i])
        runs.append(local.occupied())
    np.testing.assert_array_equal(runs[0], runs[1])


def test_backends_agree_on_simple_scene(kitti_root: Path) -> None:
    seq = open_sequence(kitti_root, "00")
    occupied, views = {}, {}
    for backend in BACKENDS:
        cfg = MapConfig(backend=backend, window=5)
        local = make_local_map(cfg)
        for i in range(4, len(seq)):
            local.insert(seq.scan(i), seq.poses[i])
        occupied[backend] = {tuple(c) for c in local.occupied()}
        xy, value = encode(local.occupied(), seq.poses[-1][2, 3], cfg)
        views[backend] = render(xy, value, pose_viewpoint(seq.poses[-1])[None], cfg)[0]
    a, b = occupied["voxel"], occupied["octomap"]
    assert len(a) > 1000
    assert len(a & b) / len(a | b) > 0.95
    assert np.mean(views["voxel"] == views["octomap"]) > 0.98
    assert (views["voxel"] == 1.0).sum() > 20  # walls and box are in view


def test_octomap_clears_what_voxel_keeps() -> None:
    """The documented difference: OctoMap's misses clear a voxel later beams pass through."""
    rng = np.random.default_rng(4)
    blob = np.array([[6.1, 0.1, 0.1, 0.0]], np.float32)
    wall = np.zeros((400, 4), np.float32)
    wall[:, 0] = 12.1
    wall[:, 1:3] = rng.uniform(-1.0, 1.0, (400, 2))
    wall[:, 1] = np.round(wall[:, 1] * 4) / 4 + 0.1
    wall[:, 2] = np.round(wall[:, 2] * 4) / 4 + 0.1
    wall = np.concatenate([wall, [[12.1, 0.1, 0.1, 0.0]]]).astype(np.float32)
    occupied = {}
    for backend in BACKENDS:
        local = make_local_map(MapConfig(backend=backend, window=10))
        local.insert(blob, _pose())
        for _ in range(4):  # beams through the blob's voxel to the wall behind it
            local.insert(wall, _pose())
        occupied[backend] = np.any(np.all(np.isclose(local.occupied(), [6.25, 0.25, 0.25]), axis=1))
    assert occupied == {"voxel": True, "octomap": False}
