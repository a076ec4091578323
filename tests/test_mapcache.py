"""The map cache: keys, hits, one pass for many conditions, determinism, the CLI."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from safl_bench import mapcache
from safl_bench.errors import ConfigError
from safl_bench.mapbuild import build_views, select_frames
from safl_bench.mapconfig import MapConfig
from safl_bench.noise import CLEAN, Condition
from safl_bench.sources import kitti_source

FRAMES = np.array([3, 7, 11])
T5 = Condition(5.0, 1.0)


def test_load_views_then_cache_hit(kitti_root: Path, safl_home: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    source = kitti_source(kitti_root)
    maps = mapcache.load_views(source, "00", MapConfig(), frames=FRAMES, condition=T5, seed=1, progress=False)
    assert isinstance(maps, np.ndarray) and maps.shape == (3, 64, 64) and maps.dtype == np.float32
    assert 0.0 <= maps.min() and maps.max() == 1.0
    files = list(safl_home.rglob("*.npz"))
    assert len(files) == 1 and str(files[0]).startswith(str(safl_home / "maps"))

    def fail(*args: object, **kwargs: object) -> None:
        raise AssertionError("rendered again instead of reading the cache")

    monkeypatch.setattr("safl_bench.mapbuild.build_views", fail)
    again = mapcache.load_views(source, "00", MapConfig(), frames=FRAMES, condition=T5, seed=1, progress=False)
    np.testing.assert_array_equal(maps, again)


def test_prepare_one_pass_matches_single_loads(kitti_root: Path, safl_home: Path) -> None:
    source = kitti_source(kitti_root)
    conds = [CLEAN, T5, Condition(1.0, 2.0)]
    paths = mapcache.prepare(source, "00", MapConfig(), frames=FRAMES, conditions=conds, seed=0,
                             kinds=["topview", "points"], progress=False)
    assert len(paths) == 6 and all(p.is_file() for p in paths.values())
    clean = mapcache.load_views(source, "00", MapConfig(), frames=FRAMES, condition=CLEAN, seed=0, progress=False)
    noisy = mapcache.load_views(source, "00", MapConfig(), frames=FRAMES, condition=T5, seed=0, progress=False)
    assert not np.array_equal(clean, noisy)  # the viewpoint moved
    pts = mapcache.load_views(source, "00", MapConfig(), frames=FRAMES, condition=CLEAN, seed=0,
                              kind="points", progress=False)
    assert isinstance(pts, list) and len(pts) == 3
    assert all(p.dtype == np.float32 and p.ndim == 2 and p.shape[1] == 3 and len(p) > 100 for p in pts)
    # rendering afresh in another home gives identical files' contents (determinism)
    direct = build_views(source.sequence("00"), MapConfig(), FRAMES, {"c": None}, ["topview"], progress=False)
    np.testing.assert_array_equal(direct["c", "topview"], clean)


def test_key_changes_with_every_config_field(kitti_root: Path) -> None:
    source = kitti_source(kitti_root)
    base = MapConfig()
    keys = {mapcache.cache_key(source, "00", base, FRAMES, T5, 0, "topview")}
    changes = {
        "size": 32, "extent_m": 60.0, "voxel_m": 0.4, "window": 5, "radius_m": 40.0,
        "backend": "octomap", "encoding": "height", "sensor_height_m": 1.5,
        "ground_clearance_m": 0.4, "min_height_m": -1.0, "max_height_m": 3.0, "ground_value": 0.4,
        "prob_hit": 0.8, "prob_miss": 0.3, "prob_occupied": 0.6, "clamp_min": 0.1, "clamp_max": 0.95,
    }
    assert set(changes) == {f.name for f in dataclasses.fields(MapConfig)}
    for name, value in changes.items():
        keys.add(mapcache.cache_key(source, "00", dataclasses.replace(base, **{name: value}), FRAMES, T5, 0, "topview"))
    keys.add(mapcache.cache_key(source, "00", base, FRAMES[:2], T5, 0, "topview"))
    keys.add(mapcache.cache_key(source, "00", base, FRAMES, Condition(5.0, 1.5), 0, "topview"))
    keys.add(mapcache.cache_key(source, "00", base, FRAMES, T5, 1, "topview"))
    keys.add(mapcache.cache_key(source, "00", base, FRAMES, T5, 0, "points"))
    assert len(keys) == len(changes) + 5
    # the seed does not matter for clean views
    assert mapcache.cache_key(source, "00", base, FRAMES, CLEAN, 0, "topview") == \
        mapcache.cache_key(source, "00", base, FRAMES, CLEAN, 9, "topview")


def test_key_follows_source_files(kitti_copy: Path) -> None:
    source = kitti_source(kitti_copy)
    before = source.fingerprint("00")
    times = kitti_copy / "sequences" / "00" / "times.txt"
    times.write_text(times.read_text() + "\n")
    assert source.fingerprint("00") != before


def test_bad_requests(kitti_root: Path, safl_home: Path) -> None:
    source = kitti_source(kitti_root)
    with pytest.raises(ConfigError, match=r"frames 0\.\.11"):
        mapcache.load_views(source, "00", MapConfig(), frames=np.array([12]), condition=CLEAN, seed=0)
    with pytest.raises(ConfigError, match="view kind"):
        mapcache.load_views(source, "00", MapConfig(), frames=FRAMES, condition=CLEAN, seed=0, kind="image")
    with pytest.raises(ConfigError, match="backend"):
        MapConfig(backend="gpu")
    assert select_frames(10, 4).tolist() == [0, 4, 8]


def test_cli_prepare_kitti(kitti_root: Path, safl_home: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from safl_bench.cli import main

    argv = ["data", "prepare", "--kitti-root", str(kitti_root), "--sequences", "00", "--step", "5",
            "--conditions", "clean", "T1R1", "--quiet"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "sequence 00: 3 frames x 2 conditions" in out and str(safl_home / "maps") in out
    files = sorted(safl_home.rglob("*.npz"))
    assert len(files) == 2
    stamps = [f.stat().st_mtime_ns for f in files]
    assert main(argv) == 0  # cache hit: nothing rewritten
    assert [f.stat().st_mtime_ns for f in files] == stamps
    assert main([*argv[:-3], "T1X", "--quiet"]) == 2
    assert "not a noise condition" in capsys.readouterr().err


def test_synth_source_calls_ensure_and_keys_on_manifest(
    tmp_path: Path, safl_home: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from conftest import write_kitti

    from safl_bench import synth
    from safl_bench.sources import resolve_source
    from safl_bench.synth.writer import manifest_path

    calls = []

    def fake_ensure(root: Path, sequences: list[str], seed: int = 0, progress: bool = True,
                    version: str = "6") -> None:
        calls.append((root, list(sequences), seed, version))
        for name in sequences:
            write_kitti(root, name, n=4)
            manifest_path(root, name).write_text(f'{{"seed": {seed}}}')

    monkeypatch.setattr(synth, "ensure", fake_ensure)
    monkeypatch.setattr(synth, "default_root", lambda seed=0, version="6": tmp_path / f"v{version}-seed-{seed}")
    source = resolve_source(None, sequences=["09"], seed=3, progress=False)
    assert calls == [(tmp_path / "v6-seed-3", ["09"], 3, synth.GENERATOR_VERSION)]
    assert source.kind == "synth" and source.label == "synthetic default (seed 3)"
    assert len(source.sequence("09")) == 4
    before = source.fingerprint("09")
    manifest_path(source.root, "09").write_text('{"seed": 4}')
    assert source.fingerprint("09") != before


def test_a_long_pass_resumes_from_the_chunks_it_finished(kitti_root: Path, safl_home: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """A pass longer than CHUNK_FRAMES keeps each finished chunk; interrupted, it renders only
    the chunks it had not finished, and its views are the one-pass ones."""
    monkeypatch.setattr(mapcache, "CHUNK_FRAMES", 4)
    source = kitti_source(kitti_root)
    frames = np.arange(12)
    real = mapcache._build_chunk
    calls: list[int] = []

    def interrupted(*args: object) -> object:
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(mapcache, "_build_chunk", interrupted)
    with pytest.raises(KeyboardInterrupt):
        mapcache.prepare(source, "00", MapConfig(), frames=frames, conditions=[CLEAN, T5], seed=0,
                         progress=False)
    kept = list(safl_home.rglob("*.parts/*.zip"))
    assert len(kept) == 2 and not list(safl_home.rglob("topview-*.npz"))
    calls.clear()
    monkeypatch.setattr(mapcache, "_build_chunk", lambda *a: (calls.append(1), real(*a))[1])
    paths = mapcache.prepare(source, "00", MapConfig(), frames=frames, conditions=[CLEAN, T5],
                             seed=0, progress=False)
    assert len(calls) == 1 and not list(safl_home.rglob("*.parts"))
    direct = build_views(source.sequence("00"), MapConfig(), frames,
                         {"clean": None, "t5": mapcache.sample_offsets(12, T5, 0)}, ["topview"],
                         progress=False)
    for cond, name in ((CLEAN, "clean"), (T5, "t5")):
        assert paths[cond, "topview"].is_file()
        views = mapcache.load_views(source, "00", MapConfig(), frames=frames, condition=cond, seed=0,
                                    progress=False)
        np.testing.assert_array_equal(views, direct[name, "topview"])
