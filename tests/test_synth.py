"""The synthetic dataset: KITTI layout, pykitti readability, determinism, revisits, scan shape."""

from __future__ import annotations

import hashlib
import itertools
from pathlib import Path

import numpy as np
import pytest

from safl_bench import synth
from safl_bench.cli import main as cli_main
from safl_bench.errors import ConfigError, DataError
from safl_bench.synth.routes import plan_trajectory, revisit_kinds, walk_revisits
from safl_bench.synth.streets import make_street_grid

# A tiny, coarse sequence: 2x2 streets, 6 frames, a 64 x 180 sensor.
TINY = synth.SynthConfig(frames=6, grid_lines=2, azimuth_res_deg=2.0)


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("synth")
    synth.ensure(root, ["00"], seed=3, progress=False, config=TINY)
    return root


def _digests(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*")) if p.is_file()
    }


def test_kitti_layout_and_pykitti(tiny_root: Path) -> None:
    import pykitti

    seq = tiny_root / "sequences" / "00"
    assert sorted(p.name for p in (seq / "velodyne").iterdir()) == [f"{i:06d}.bin" for i in range(6)]
    for line in (seq / "calib.txt").read_text().splitlines():
        key, values = line.split(":")
        assert key in {"P0", "P1", "P2", "P3", "Tr"} and len(values.split()) == 12
    assert len((seq / "times.txt").read_text().split()) == 6
    pose_lines = (tiny_root / "poses" / "00.txt").read_text().splitlines()
    assert len(pose_lines) == 6 and all(len(line.split()) == 12 for line in pose_lines)

    data = pykitti.odometry(str(tiny_root), "00")
    assert len(data) == 6
    np.testing.assert_allclose(data.poses[0], np.eye(4), atol=1e-12)
    velo = data.get_velo(2)
    assert velo.dtype == np.float32 and velo.shape[1] == 4 and len(velo) > 1000
    assert 0 <= velo[:, 3].min() and velo[:, 3].max() <= 1
    # camera poses convert back to planar LiDAR poses (x forward, y left, z up)
    tr = data.calib.T_cam0_velo
    lidar = np.linalg.inv(tr) @ np.asarray(data.poses) @ tr
    assert np.all(np.abs(lidar[:, 2, 3]) < 0.05)  # essentially planar
    step = np.linalg.norm(np.diff(lidar[:, :2, 3], axis=0), axis=1)
    assert np.all((step > 0.3) & (step < 1.4))  # 3-14 m/s at 10 Hz
    t = np.array([x.total_seconds() for x in data.timestamps])
    assert np.all(np.abs(np.diff(t) - 0.1) < 0.01)


def test_same_seed_same_bytes(tiny_root: Path, tmp_path: Path) -> None:
    synth.ensure(tmp_path, ["00"], seed=3, progress=False, config=TINY)
    assert _digests(tmp_path) == _digests(tiny_root)
    other = tmp_path / "other"
    synth.ensure(other, ["00"], seed=4, progress=False, config=TINY)
    assert _digests(other) != _digests(tmp_path)


def test_threads_do_not_change_bytes(tmp_path: Path) -> None:
    """Two sequences generated at once (two threads) equal the same ones made one by one."""
    together, apart = tmp_path / "together", tmp_path / "apart"
    synth.ensure(together, ["00", "01"], seed=5, progress=False, config=TINY)
    for name in ("01", "00"):
        synth.ensure(apart, [name], seed=5, progress=False, config=TINY)
    assert _digests(together) == _digests(apart)


def test_ensure_redoes_only_missing_or_stale(tmp_path: Path) -> None:
    synth.ensure(tmp_path, ["01"], seed=0, progress=False, config=TINY)
    assert synth.is_current(tmp_path, "01", 0, TINY)
    scan = tmp_path / "sequences" / "01" / "velodyne" / "000003.bin"
    before = scan.stat().st_mtime_ns
    synth.ensure(tmp_path, ["01"], seed=0, progress=False, config=TINY)  # nothing to do
    assert scan.stat().st_mtime_ns == before
    scan.write_bytes(scan.read_bytes()[:-16])  # a truncated scan, as after a crash
    assert not synth.is_current(tmp_path, "01", 0, TINY)
    (tmp_path / "sequences" / "01" / "synth_manifest.json").unlink()  # no manifest: incomplete
    assert not synth.is_current(tmp_path, "01", 0, TINY)
    synth.ensure(tmp_path, ["01"], seed=0, progress=False, config=TINY)
    assert synth.is_current(tmp_path, "01", 0, TINY)
    assert not synth.is_current(tmp_path, "01", 1, TINY)  # another seed is stale


@pytest.mark.parametrize("name", ["00", "09"])
def test_default_test_routes_revisit(name: str) -> None:
    """The default test routes come back to places driven before (no ray casting needed)."""
    scene = synth.make_route(name, seed=synth.DEFAULT_SEED)
    poses = scene.lidar_poses()
    assert np.allclose(poses[0], np.eye(4))
    n = len(poses)
    assert n == synth.SynthConfig().spec(name).frames
    xy = poses[:, :2, 3]
    heading = np.arctan2(poses[:, 1, 0], poses[:, 0, 0])
    speed = np.linalg.norm(np.diff(xy, axis=0), axis=1) * 10
    assert 7.0 < speed.mean() < 12.0 and speed.max() < 14.0
    same, opposite = revisit_kinds(xy, heading, scene.trajectory.times)
    if name == "00":  # KITTI 00's kind: the same way only
        assert same.sum() > 20 and opposite.sum() == 0
    else:  # KITTI 08's kind: the opposite way
        assert opposite.sum() > 20


@pytest.mark.parametrize("revisits", ["same", "opposite", "both"])
def test_route_revisit_kinds(revisits: str) -> None:
    """A route drives again what its `revisits` asks for, and "same" never the opposite way."""
    grid = make_street_grid(4, np.random.default_rng(3))
    for seed in range(3):
        traj = plan_trajectory(grid, 900, np.random.default_rng(seed),
                               wander_rng=np.random.default_rng(seed), revisits=revisits)
        same, opposite = walk_revisits(list(traj.nodes))
        assert {"same": same and not opposite, "opposite": opposite, "both": same and opposite}[revisits]


#: SHA-256 (first 16 hex) of data version 5's route of 00, seed 0, as that version made it: its
#: walk (the crossings, int64) and its positions rounded to the millimetre. The float bytes
#: themselves differ between CPUs in the last bits (an AMD EPYC and the Intel Xeon the records
#: were made on), so they are not what is pinned.
WALK_00_V5 = "a61324060e352ec5"
ROUTE_00_V5_MM = "6d10a5c99f7ab9b4"


def _loops_and_passes(scene: synth.generate.Scene) -> tuple[float, int]:
    """The shortest plan-frame driving between two visits of a crossing in a scene's walk, and
    the most times one street was driven the same way."""
    grid, walk = scene.grid, list(scene.trajectory.nodes)
    driven, seen, shortest = 0.0, {walk[0]: 0.0}, np.inf
    edges: dict[tuple[tuple[int, int], tuple[int, int]], int] = {}
    for a, b in itertools.pairwise(walk):
        driven += abs(grid.u_lines[a[0]] - grid.u_lines[b[0]]) + abs(grid.v_lines[a[1]] - grid.v_lines[b[1]])
        if b in seen:
            shortest = min(shortest, driven - seen[b])
        seen[b] = driven
        edges[(a, b)] = edges.get((a, b), 0) + 1
    return float(shortest), max(edges.values())


def test_data_version_6_routes_come_back_through_other_streets() -> None:
    """Version 6's walks obey the loop rule on every default sequence (no lap of one block, no
    street a third time); version 5's route of 00 is the one it always was, a lap of a block."""
    from safl_bench.analysis.fidelity import route_measures
    from safl_bench.synth.routes import MAX_PASSES, MIN_LOOP_M

    for seed in range(3):
        for name in synth.ALL_SEQUENCES:
            scene = synth.make_route(name, seed, version="6")
            shortest, passes = _loops_and_passes(scene)
            assert shortest >= MIN_LOOP_M and passes <= MAX_PASSES, (seed, name)
            route = route_measures(scene.trajectory.xy, scene.trajectory.times)
            assert route.short_lap_share == 0.0 and route.third_pass_share == 0.0, (seed, name)
    old = synth.make_route("00", 0, version="5")
    walk = np.asarray(old.trajectory.nodes, np.int64)
    assert hashlib.sha256(walk.tobytes()).hexdigest()[:16] == WALK_00_V5
    assert hashlib.sha256(np.round(old.trajectory.xy, 3).tobytes()).hexdigest()[:16] == ROUTE_00_V5_MM
    assert _loops_and_passes(old)[0] < MIN_LOOP_M
    assert route_measures(old.trajectory.xy, old.trajectory.times).short_lap_share > 0.2
    assert synth.SynthConfig().spec("09", "5").frames == 800
    assert synth.SynthConfig().spec("09", "6").frames == 1000


def test_each_data_version_has_its_own_folder(safl_home: Path) -> None:
    assert synth.default_root(0, "5") == safl_home / "synth" / "seed-0"
    assert synth.default_root(2, "6") == safl_home / "synth" / "v6" / "seed-2"
    assert synth.default_root(1) == synth.default_root(1, synth.GENERATOR_VERSION)
    with pytest.raises(DataError, match=r"generates synthetic data versions 5, 6, not '4'"):
        synth.ensure(safl_home / "x", ["01"], version="4")


def test_route_revisit_kind_unknown() -> None:
    grid = make_street_grid(3, np.random.default_rng(0))
    with pytest.raises(ConfigError, match=r"'same'.*'backwards'"):
        plan_trajectory(grid, 50, np.random.default_rng(0), wander_rng=np.random.default_rng(0),
                        revisits="backwards")


def test_default_sequence_lengths() -> None:
    cfg = synth.SynthConfig()
    assert 1200 <= cfg.spec("00").frames <= 1500
    assert set(synth.TEST_SEQUENCES).isdisjoint(synth.TRAIN_SEQUENCES)


def test_single_scan_looks_like_a_street() -> None:
    """One full-resolution scan: KITTI-like count, mostly ground, some tall structure."""
    cfg = synth.SynthConfig(frames=2, grid_lines=2)
    scene = synth.make_route("02", seed=1, config=cfg)
    world, lidar = synth.make_scene_world(scene)
    pts = lidar.scan(world, scene.poses[1], key=7, azimuth_offset=0.0)
    assert pts.dtype == np.float32 and pts.shape[1] == 4
    assert 30_000 < len(pts) < 130_000
    r = np.linalg.norm(pts[:, :3], axis=1)
    assert r.min() > 2.0 and r.max() <= cfg.max_range_m + 0.5
    ground = pts[:, 2] < -1.4
    assert 0.4 < ground.mean() < 0.9  # mostly ground, like KITTI (~0.5)
    assert (pts[:, 2] > 0.5).mean() > 0.01  # facades, trees, poles
    assert 3.0 < np.median(r) < 25.0
    assert 0.0 <= pts[:, 3].min() and pts[:, 3].max() <= 1.0 and 0.1 < np.median(pts[:, 3]) < 0.5
    elev = np.degrees(np.arcsin(pts[:, 2] / r))
    assert elev.min() > -26.5 and elev.max() < 3.5


def test_cli_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    assert cli_main(["data", "synth", "--out", str(a_file), "--sequences", "00"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "not a directory" in err
    assert cli_main(["data", "synth", "--out", str(tmp_path), "--sequences", "77"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "'77'" in err
    assert cli_main(["data", "show", "--root", str(tmp_path), "--sequence", "05",
                     "--out", str(tmp_path / "x.png")]) == 2
    assert "\n" not in capsys.readouterr().err.strip()
    assert cli_main(["data", "show", "--sequence", "77"]) == 2


def test_cli_show_draws_png(tiny_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "show.png"
    assert cli_main(["data", "show", "--root", str(tiny_root), "--sequence", "00",
                     "--out", str(out), "--scans", "2"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_vehicle_follows_the_land() -> None:
    from safl_bench.synth.generate import make_route, make_scene_world
    from safl_bench.synth.terrain import make_terrain

    terrain = make_terrain(np.random.default_rng(3))
    x, y, h = np.array([10.0, 250.0]), np.array([-40.0, 600.0]), 1e-4
    gx, gy = terrain.gradient(x, y)
    assert np.allclose(gx, (terrain.height(x + h, y) - terrain.height(x - h, y)) / (2 * h), atol=1e-6)
    assert np.allclose(gy, (terrain.height(x, y + h) - terrain.height(x, y - h)) / (2 * h), atol=1e-6)

    scene = make_route("01", 0, synth.SynthConfig(frames=60))
    world, _ = make_scene_world(scene)
    poses = scene.poses
    ground = scene.grid.terrain.height(poses[:, 0, 3], poses[:, 1, 3])
    assert np.ptp(ground) > 0.05  # the land is not flat under the route
    assert np.allclose(poses[:, 2, 3] - ground, scene.config.sensor_height_m)
    # the world raster's road surface under the vehicle is the same land (to the cell's size)
    iy = (poses[:, 1, 3] / world.cell).astype(int)
    ix = (poses[:, 0, 3] / world.cell).astype(int)
    assert np.abs(world.ground[iy, ix] - ground).max() < 0.05
    # nose up when the road climbs ahead: the forward axis points up the slope
    climb = np.diff(ground)
    forward_z = poses[:-1, 2, 0]
    big = np.abs(climb) > 0.02
    assert big.any() and np.mean(np.sign(forward_z[big]) == np.sign(climb[big])) > 0.9


def test_the_vehicle_wanders_in_its_lane() -> None:
    """Revisits see the street from a slightly different lateral position (data version 3), the
    path stays smooth and the vehicle stays within its lane range."""
    from safl_bench.synth.routes import WANDER_RANGE_M, lane_wander

    rng = np.random.default_rng(5)
    ends = np.array([400, 900, 1500])
    w = lane_wander(ends, 1500, 0.25, rng)
    assert w.min() >= WANDER_RANGE_M[0] and w.max() <= WANDER_RANGE_M[1]
    assert np.abs(np.diff(w)).max() < 0.02  # under 2 cm of sideways drift per 0.25 m of travel
    assert w.std() > 0.05

    scene = synth.make_route("00", seed=synth.DEFAULT_SEED)
    traj = scene.trajectory
    heading_step = np.abs(np.angle(np.exp(1j * np.diff(traj.heading))))
    assert np.median(heading_step) < np.radians(0.2)  # straight streets stay straight
    lateral = []
    old = traj.times[:, None] - traj.times[None, :] > 30.0
    dist = np.linalg.norm(traj.xy[:, None] - traj.xy[None], axis=2)
    same_way = np.abs(np.angle(np.exp(1j * (traj.heading[:, None] - traj.heading[None])))) < np.pi / 4
    for i in np.flatnonzero((old & (dist < 5.0) & same_way).any(axis=1)):
        cand = np.flatnonzero(old[i] & (dist[i] < 5.0) & same_way[i])
        j = cand[np.argmin(dist[i, cand])]
        v = traj.xy[j] - traj.xy[i]
        lateral.append(abs(-np.sin(traj.heading[i]) * v[0] + np.cos(traj.heading[i]) * v[1]))
    assert len(lateral) > 20 and np.median(lateral) > 0.05  # data version 2: 0.00


def test_a_parked_car_is_seen_through_its_windows() -> None:
    """Beams pass a parked car's windows and return from inside it (data version 5), as on real
    KITTI, where parked cars fill their footprint in BEVPlace's images; a solid box returned only
    from its outside. Its top is shaped (bonnet and boot below the roof)."""
    from safl_bench.bevdensity import density_counts
    from safl_bench.mapconfig import bev_density_config
    from safl_bench.synth import materials as M
    from safl_bench.synth.lidar import Lidar
    from safl_bench.synth.world import World, _Plan, _Town

    cfg = synth.SynthConfig()
    inside, filled = [], []
    for seed in range(3):
        plan = _Plan(60.0, 60.0, 0.2)
        town = _Town(None, plan, np.random.default_rng(seed))  # type: ignore[arg-type]  # no streets
        town.car(True, 30.0, 36.0)  # along y at x = 36 m: 6 m ahead of a sensor at (30, 30) m
        car = (plan.tm == M.CAR) | (plan.tm == M.GLASS)
        assert (plan.tm == M.GLASS).sum() > 0.3 * car.sum()
        assert np.ptp(plan.top[car]) > 0.5  # bonnet and boot lie well below the roof
        world = World(0.2, plan.g, plan.gm, plan.top, plan.tm, plan.lo, plan.hi, plan.fm,
                      None)  # type: ignore[arg-type]
        pose = np.eye(4)
        pose[:3, 3] = (30.0, 30.0, float(plan.g[150, 150]) + cfg.sensor_height_m)
        pts = Lidar(cfg, np.random.default_rng(1)).scan(world, pose, key=3, azimuth_offset=0.0)
        xyz = pts[:, :3] + pose[:3, 3]
        ix, iy = (xyz[:, 0] / 0.2).astype(int), (xyz[:, 1] / 0.2).astype(int)
        on_car = car[iy, ix]
        # returns from within the car's volume: more than 0.15 m below its top there
        inside.append(int((on_car & (xyz[:, 2] < plan.top[iy, ix] - 0.15)).sum()))
        counts = density_counts(pts, bev_density_config())
        c0 = (counts.shape[0] - 1) // 2
        footprint = counts[c0 - 17:c0 - 12, c0 - 5:c0 + 6]  # 5.1-6.9 m ahead, 2 m either side
        filled.append((footprint > 0).mean())
    assert min(inside) > 20
    assert np.mean(filled) > 0.6  # a solid box: 0.58 (of the footprint's pixels, 6 m ahead)


def test_a_streamed_sequence_casts_the_scans_a_written_one_stores(tmp_path, monkeypatch):
    """The long drive's scans are cast on demand (no .bin files), and each equals the scan the
    generator would have written; its poses and times are the written sequence's."""
    from safl_bench.sources.synth import StreamedSequence, SynthSource
    from safl_bench.synth import generate

    streamed = tmp_path / "streamed"
    synth.ensure(streamed, ["L0"], seed=3, progress=False, config=TINY)
    assert synth.is_streamed(streamed, "L0") and synth.is_current(streamed, "L0", 3, TINY)
    assert not list((streamed / "sequences" / "L0" / "velodyne").glob("*.bin"))
    monkeypatch.setattr(generate, "STREAMED_SEQUENCES", ())  # the same sequence, written
    written = tmp_path / "written"
    synth.ensure(written, ["L0"], seed=3, progress=False, config=TINY)
    monkeypatch.undo()
    assert len(list((written / "sequences" / "L0" / "velodyne").glob("*.bin"))) == 6
    cast = SynthSource(root=streamed, label="s", seed=3).sequence("L0")
    read = SynthSource(root=written, label="w", seed=3).sequence("L0")
    assert isinstance(cast, StreamedSequence) and not isinstance(read, StreamedSequence)
    assert len(cast) == len(read) == 6
    np.testing.assert_array_equal(cast.poses, read.poses)
    np.testing.assert_array_equal(cast.times, read.times)
    for i in (0, 5):
        np.testing.assert_array_equal(cast.scan(i), read.scan(i))
    with pytest.raises(DataError, match="scan index 6 out of range"):
        cast.scan(6)
