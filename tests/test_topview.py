"""Projection invariants: known point -> known pixel, rotation, noise moves the viewpoint."""

from __future__ import annotations

import numpy as np
import pytest

from safl_bench.mapconfig import MapConfig
from safl_bench.topview import encode, noisy_viewpoints, render, scan_topview, view_points

CFG = MapConfig(size=64, extent_m=64.0)  # 1 m pixels


def _pixel(xy: tuple[float, float], vp: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> tuple[int, int]:
    img = render(np.array([xy]), np.array([1.0], np.float32), np.array([vp]), CFG)[0]
    hits = np.argwhere(img == 1.0)
    assert len(hits) == 1
    return int(hits[0][0]), int(hits[0][1])


def test_known_points_land_in_known_pixels() -> None:
    # row = floor(32 - forward), column = floor(32 - left)
    assert _pixel((10.5, 0.5)) == (21, 31)  # ahead, slightly left: upper half
    assert _pixel((-3.5, -7.5)) == (35, 39)  # behind and right: lower right
    assert _pixel((0.5, 20.5)) == (31, 11)  # left: left half
    # the same point seen from a viewpoint turned left 90 degrees is now to the right
    assert _pixel((0.5, 20.5), (0.0, 0.0, np.pi / 2)) == (11, 32)
    # and from a viewpoint 10 m ahead it is 10 m closer
    assert _pixel((10.5, 0.5), (10.0, 0.0, 0.0)) == (31, 31)


def test_outside_extent_is_dropped() -> None:
    img = render(np.array([[40.0, 0.0], [0.0, -33.0]]), np.ones(2, np.float32), np.zeros((1, 3)), CFG)
    assert img.sum() == 0


def _scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    # points at pixel centres (no boundary ties), mixed values
    cells = rng.integers(-32, 32, size=(300, 2))
    return cells + 0.5, rng.choice(np.array([0.5, 1.0], np.float32), size=300)


@pytest.mark.parametrize("k", [1, 2, 3])
def test_turning_viewpoint_turns_map(k: int) -> None:
    xy, value = _scene(np.random.default_rng(0))
    base = render(xy, value, np.zeros((1, 3)), CFG)[0]
    turned = render(xy, value, np.array([[0.0, 0.0, k * np.pi / 2]]), CFG)[0]
    np.testing.assert_array_equal(turned, np.rot90(base, -k))


def test_turning_viewpoint_by_small_angle_turns_about_centre() -> None:
    xy = np.array([[20.0, 0.0]])
    img = render(xy, np.ones(1, np.float32), np.array([[0.0, 0.0, np.deg2rad(30)]]), CFG)[0]
    r, c = np.argwhere(img)[0]
    fwd, left = 32 - r - 0.5, 32 - c - 0.5  # pixel centre in the view frame
    assert np.hypot(fwd, left) == pytest.approx(20.0, abs=1.0)
    assert np.degrees(np.arctan2(left, fwd)) == pytest.approx(-30.0, abs=3.0)


def test_noise_offsets_are_in_robot_frame() -> None:
    vp = np.array([[5.0, 2.0, np.pi / 2]])  # facing +y
    moved = noisy_viewpoints(vp, np.array([[1.0, 0.0, 0.1]]))  # 1 m forward
    np.testing.assert_allclose(moved, [[5.0, 3.0, np.pi / 2 + 0.1]], atol=1e-12)
    moved = noisy_viewpoints(vp, np.array([[0.0, 1.0, 0.0]]))  # 1 m left
    np.testing.assert_allclose(moved, [[4.0, 2.0, np.pi / 2]], atol=1e-12)


def test_encoding_bands() -> None:
    cfg = MapConfig()
    ground_z = -cfg.sensor_height_m
    centres = np.array([[1, 0, ground_z + 0.1], [2, 0, ground_z + 1.5], [3, 0, ground_z + 10], [4, 0, ground_z - 5]])
    xy, value = encode(centres, 0.0, cfg)
    np.testing.assert_array_equal(xy, [[1, 0], [2, 0]])  # too high / too low dropped
    np.testing.assert_array_equal(value, [cfg.ground_value, 1.0])
    hcfg = MapConfig(encoding="height")
    _, hv = encode(centres, 0.0, hcfg)
    assert hv[0] == pytest.approx(0.25) and hv[1] == pytest.approx(0.5 + 0.5 * 1.5 / hcfg.max_height_m)
    # obstacle wins over ground in a shared pixel
    img = render(np.array([[0.2, 0.2], [0.3, 0.3]]), np.array([1.0, 0.5], np.float32), np.zeros((1, 3)), CFG)
    assert img.max() == 1.0


def test_view_points_frame() -> None:
    pts = view_points(np.array([[5.0, 3.0, 1.0]]), np.array([5.0, 2.0, np.pi / 2]), robot_z=0.5)
    assert pts.dtype == np.float32
    np.testing.assert_allclose(pts, [[1.0, 0.0, 0.5]], atol=1e-6)


def test_view_points_keep_what_the_top_view_shows() -> None:
    """Cropped to the top view's window: a moved viewpoint sees another part of the map, and
    every kept point lands in a pixel of the top view of the same viewpoint."""
    rng = np.random.default_rng(0)
    centres = np.column_stack([rng.uniform(-60, 60, (4000, 2)), rng.uniform(-1, 3, 4000)])
    h = CFG.extent_m / 2
    vp = np.array([3.0, -2.0, 0.7])
    pts = view_points(centres, vp, robot_z=0.0, half_extent_m=h)
    full = view_points(centres, vp, robot_z=0.0)
    assert 0 < len(pts) < len(full)
    assert (pts[:, 0] > -h).all() and (pts[:, 0] <= h).all() and (np.abs(pts[:, 1]) <= h).all()
    inside = (full[:, 0] > -h) & (full[:, 0] <= h) & (full[:, 1] > -h) & (full[:, 1] <= h)
    np.testing.assert_array_equal(pts, full[inside])
    for x, y in pts[:50, :2].astype(np.float64):  # each kept point fills a pixel of the view
        img = render(np.array([[vp[0] + np.cos(vp[2]) * x - np.sin(vp[2]) * y,
                                vp[1] + np.sin(vp[2]) * x + np.cos(vp[2]) * y]]),
                     np.array([1.0], np.float32), vp[None], CFG)
        assert img.max() == 1.0
    moved = view_points(centres, vp + np.array([20.0, 0.0, 0.0]), robot_z=0.0, half_extent_m=h)
    assert len(moved) != len(pts)


def test_scan_topview_is_deterministic() -> None:
    rng = np.random.default_rng(3)
    scan = rng.uniform(-30, 30, size=(5000, 4)).astype(np.float32)
    scan[:, 2] = rng.uniform(-2.0, 2.0, 5000)
    a, b = scan_topview(scan), scan_topview(scan.copy())
    assert a.shape == (64, 64) and a.dtype == np.float32
    assert 0.0 <= a.min() and a.max() <= 1.0 and set(np.unique(a)) <= {0.0, 0.5, 1.0}
    np.testing.assert_array_equal(a, b)
