"""The BEV-density encoding (BEVPlace's images): counts of hand-made clouds, geometry, viewpoint
noise, and its way through the map builder, the cache and `data prepare`."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from safl_bench import mapcache
from safl_bench.bevdensity import (
    DENSITY_CAP,
    SCRIPT_MIN_COUNT,
    density_counts,
    density_image,
    density_levels,
    density_views,
    offset_transform,
)
from safl_bench.errors import ConfigError
from safl_bench.mapbuild import build_views
from safl_bench.mapconfig import ENCODINGS, MapConfig, bev_density_config, config_for_encoding
from safl_bench.noise import CLEAN, Condition
from safl_bench.sources import kitti_source
from safl_bench.topview import encode, scan_topview

CFG = bev_density_config()
C0 = 75
RES = 0.4
VOX = 0.3


def _column(x: float, y: float, n: int, per_voxel: int = 1) -> np.ndarray:
    """Points in n stacked 0.3 m voxels of one column (voxel z index -4 .. n - 5, all above the
    ground cut at z = -1.2 m), `per_voxel` points in each (1 cm apart in z), all at (x, y)."""
    z = (np.arange(-4, n - 4) + 0.5) * VOX
    z = (z[:, None] + 0.01 * np.arange(per_voxel)[None, :]).ravel()
    return np.stack([np.full(z.size, x), np.full(z.size, y), z], axis=1)


def test_config_is_bevplace() -> None:
    assert (CFG.size, CFG.cell_m, CFG.voxel_m, CFG.window, CFG.radius_m) == (151, 0.4, 0.3, 1, 25.0)
    assert CFG.encoding == "bev-density" and "bev-density" in ENCODINGS
    assert CFG.min_height_m - CFG.sensor_height_m == pytest.approx(-1.2)
    assert config_for_encoding("bev-density") == CFG
    assert config_for_encoding("height") == dataclasses.replace(MapConfig(), encoding="height")
    assert bev_density_config(window=3).window == 3
    assert bev_density_config(min_height_m=0.7).min_height_m == 0.7  # no ground band to stay below
    with pytest.raises(ConfigError, match="min_height_m < max_height_m"):
        bev_density_config(min_height_m=30.0)
    with pytest.raises(ConfigError, match="even"):
        MapConfig(size=151)  # odd sizes only for the bev-density encoding
    with pytest.raises(ConfigError, match="rendered from points"):
        encode(np.zeros((1, 3)), 0.0, CFG)


def test_known_counts_of_a_hand_made_cloud() -> None:
    # x = 0.4 k + 0.1: inside pixel row 75 - k under both BEVPlace's truncation and the
    # image source's rounding (row = rint(c0 - x / res))
    cloud = np.concatenate([
        _column(4.9, 3.3, 4),             # 4 voxels -> count 4
        _column(-4.9, -3.3, 12),          # 12 voxels -> clipped at 10
        _column(10.1, -2.1, 1),           # a single count (kept by default)
        _column(2.1, 8.1, 3, per_voxel=5),  # 5 points per voxel still count once per voxel
        [[4.9, 3.3, -1.5], [4.9, 3.3, 25.5], [25.5, 0.1, 0.0], [0.1, -25.5, 0.0]],  # cut / cropped
    ])
    counts = density_counts(cloud, CFG)
    expect = {(75 - 12, 75 - 8): 4, (75 + 12, 75 + 8): DENSITY_CAP, (75 - 25, 75 + 5): 1, (75 - 5, 75 - 20): 3}
    assert {tuple(map(int, rc)): int(counts[tuple(rc)]) for rc in np.argwhere(counts)} == expect
    for (r, c) in expect:  # the image source's convention agrees on these points
        assert (r, c) in {(int(np.rint(C0 - x / RES)), int(np.rint(C0 - y / RES)))
                          for x, y in [(4.9, 3.3), (-4.9, -3.3), (10.1, -2.1), (2.1, 8.1)]}
    image = density_image(cloud, CFG)
    assert image.dtype == np.float32 and image.shape == (151, 151)
    levels = np.rint(image * 255).astype(int)
    assert levels[63, 67] == 102 and levels[87, 83] == 255 and levels[50, 80] == 26 and levels[70, 55] == 76
    np.testing.assert_array_equal(image, np.rint(image * 255) / np.float32(255))  # PNG levels
    # BEVPlace's script drops single counts (the published images do not)
    script = density_counts(cloud, CFG, min_count=SCRIPT_MIN_COUNT)
    assert script[50, 80] == 0 and script[63, 67] == 4
    assert np.array_equal(scan_topview(cloud, CFG), image)


def test_orientation_and_truncation() -> None:
    def pixel(x: float, y: float) -> tuple[int, int]:
        hits = np.argwhere(density_counts(_column(x, y, 2), CFG))
        assert len(hits) == 1
        return int(hits[0][0]), int(hits[0][1])

    assert pixel(10.1, 0.5) == (50, 74)   # ahead: up; slightly left: left of centre
    assert pixel(0.5, 10.1) == (74, 50)   # left: left
    assert pixel(-10.1, -0.5) == (100, 76)  # behind and right: down and right
    # row = c0 - trunc(x / res): the centre row is two cells wide (-0.4 m < x < 0.4 m)
    assert pixel(0.3, 5.1) == pixel(-0.3, 5.1) == (75, 63)
    assert pixel(0.41, 5.1)[0] == 74 and pixel(-0.41, 5.1)[0] == 76


def test_levels_scale_by_the_image_maximum() -> None:
    counts = np.zeros((2, 3, 3), np.int32)
    counts[0, 0, :] = [1, 2, 3]
    np.testing.assert_array_equal(density_levels(counts)[0, 0], [85, 170, 255])
    assert density_levels(counts)[1].max() == 0  # an empty image stays empty


def _random_cloud(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    blocks = rng.uniform([5, 5, -1.1], [20, 20, 2.0], (4000, 3))
    walls = rng.uniform([-20, -18, -1.1], [18, -16, 3.0], (3000, 3))
    return np.concatenate([blocks, walls])


def test_viewpoint_noise_moves_the_view() -> None:
    cloud = _random_cloud()
    pose = np.eye(4)
    clean, moved, turned = density_views([(cloud, pose)], pose, [None, [1.2, -1.2, 0.0], [0, 0, np.pi / 2]], CFG)
    # 1.2 m forward and 1.2 m right: the scene comes 3 rows down and 3 columns left; the voxel
    # grid moves with the viewpoint (4 voxels), so the counts are the same
    np.testing.assert_array_equal(moved[30:72, 30:72], clean[27:69, 33:75])
    # turning left by 90 degrees turns the image clockwise, exactly (odd size, truncation)
    np.testing.assert_array_equal(turned, np.rot90(clean, -1))
    np.testing.assert_allclose(offset_transform([1.0, 2.0, 0.5])[:2, 3], [1.0, 2.0])


def _shift_m(a: np.ndarray, b: np.ndarray, cell: float, axis: int) -> float:
    """The shift (m) along `axis` that best lays b's non-zero pixels on a's."""
    best = max(range(-15, 16), key=lambda s: int(((np.roll(a, s, axis) > 0) & (b > 0)).sum()))
    return best * cell


@pytest.mark.parametrize("offset, axis, expect_m", [((2.5, 0.0, 0.0), 0, 2.5), ((0.0, 2.5, 0.0), 1, 2.5)])
def test_noise_moves_density_view_as_it_moves_occupancy_view(
    kitti_root: Path, offset: tuple[float, float, float], axis: int, expect_m: float,
) -> None:
    seq = kitti_source(kitti_root).sequence("00")
    off = {"clean": None, "moved": np.array([offset])}
    for config in (MapConfig(), CFG):
        views = build_views(seq, config, np.array([8]), off, ["topview"], progress=False)
        clean, moved = views["clean", "topview"][0], views["moved", "topview"][0]
        assert clean.any() and not np.array_equal(clean, moved)
        # moving the viewpoint forward (left) brings the scene down (right) by as many metres
        assert _shift_m(clean, moved, config.cell_m, axis) == pytest.approx(expect_m, abs=config.cell_m)


def test_pipeline_cache_and_points(kitti_root: Path, safl_home: Path) -> None:
    source = kitti_source(kitti_root)
    frames = np.array([2, 6, 10])
    t1 = Condition(1.0, 1.0)
    assert mapcache.cache_key(source, "00", CFG, frames, CLEAN, 0, "topview") != \
        mapcache.cache_key(source, "00", MapConfig(), frames, CLEAN, 0, "topview")
    paths = mapcache.prepare(source, "00", CFG, frames=frames, conditions=[CLEAN, t1], seed=0,
                             kinds=["topview", "points"], progress=False)
    assert len(paths) == 4
    views = mapcache.load_views(source, "00", CFG, frames=frames, condition=CLEAN, seed=0, progress=False)
    assert isinstance(views, np.ndarray) and views.shape == (3, 151, 151) and views.max() == 1.0
    np.testing.assert_array_equal(views, np.rint(views * 255) / np.float32(255))
    # a single clean scan: exactly the scan's own image
    seq = source.sequence("00")
    np.testing.assert_array_equal(views[1], density_image(seq.scan(6), CFG))
    noisy = mapcache.load_views(source, "00", CFG, frames=frames, condition=t1, seed=0, progress=False)
    assert not np.array_equal(views, noisy)
    pts = mapcache.load_views(source, "00", CFG, frames=frames, condition=CLEAN, seed=0, kind="points", progress=False)
    assert isinstance(pts, list) and all(len(p) > 50 for p in pts)
    # a window of three scans pools their points: at least as many counts
    three = build_views(seq, bev_density_config(window=3), frames, {"c": None}, progress=False)["c", "topview"]
    assert (np.asarray(three) > 0).sum() >= (views > 0).sum()


def test_cli_prepare_bev_density(kitti_root: Path, safl_home: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from safl_bench.cli import main

    argv = ["data", "prepare", "--kitti-root", str(kitti_root), "--sequences", "00", "--step", "6",
            "--conditions", "clean", "--encoding", "bev-density", "--quiet"]
    assert main(argv) == 0
    assert "sequence 00: 2 frames x 1 conditions" in capsys.readouterr().out
    (path,) = safl_home.rglob("*.npz")
    with np.load(path) as data:
        assert data["maps"].shape == (2, 151, 151)
        assert '"encoding": "bev-density"' in str(data["meta"]) and '"voxel_m": 0.3' in str(data["meta"])
