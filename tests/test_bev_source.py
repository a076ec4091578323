"""The top-view image source (`--bev-root`): reading, caching, bad input, tasks and records on it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import write_bev

from safl_bench import tasks
from safl_bench.cli import main as cli_main
from safl_bench.errors import ConfigError, DataError
from safl_bench.resample import coverage, fit_input, move_viewpoint
from safl_bench.sources import bev as bev_module
from safl_bench.sources import bev_source
from safl_bench.views.render import build_views as render_views

REVISIT = "Test/BevTiny-Revisit-v0"
RANGES = "Test/BevTiny-BEVPlace-v0"
PAPER = "Test/BevTiny-T1R0.2-v0"


@pytest.fixture
def tiny_bev_tasks():
    """Small tasks on the fixture folder's sequence 00 (its frames are 1 s apart)."""
    specs = [
        tasks.register(REVISIT, source="bev", sequence="00", protocol="revisit", step=1,
                       tp_radius_m=3.0, fp_radius_m=20.0, window_s=5.0),
        tasks.register(RANGES, source="bev", sequence="00", protocol="bevplace", step=1,
                       database_frames=(0, 20), query_frames=(20, 40), tp_radius_m=5.0, fp_radius_m=5.0),
        tasks.register(PAPER, source="bev", sequence="00", condition="T1R0.2", step=2),
    ]
    yield [s.id for s in specs]
    for s in specs:
        tasks.unregister(s.id)


def test_sequence_reads_poses_times_and_assumes_10_hz_without_times(tmp_path: Path) -> None:
    root = write_bev(tmp_path / "a", n=10)
    seq = bev_source(root).sequence("00")
    assert len(seq) == 10 and seq.positions.shape == (10, 2)
    np.testing.assert_allclose(seq.positions[-1], [0.0, 0.0], atol=1e-6)  # driven back home
    np.testing.assert_allclose(seq.times, np.arange(10.0))
    assert bev_source(root).notes("00") == [
        f"top views: the images of {root / '00' / 'imgs'}, 0.4 m per pixel"]
    bare = write_bev(tmp_path / "b", n=10, times=False)
    source = bev_source(bare)
    np.testing.assert_allclose(source.sequence("00").times, np.arange(10) * 0.1)
    assert any("taken as 10 Hz" in note for note in source.notes("00"))


def test_images_are_cached_and_views_are_value_over_255(bev_root: Path, safl_home: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    source = bev_source(bev_root)
    views = render_views(source, "00", None, np.arange(0, 40, 4), {"T0R0": None})["T0R0", "topview"]
    assert views.shape == (10, 41, 41) and views.dtype == np.float32
    raw = np.asarray(__import__("PIL.Image", fromlist=["Image"]).open(bev_root / "00/imgs/000004.png"))
    np.testing.assert_array_equal(views[1], raw.astype(np.float32) / 255)
    assert list(safl_home.rglob("images-*.npy"))

    def fail(*args: object, **kwargs: object) -> None:
        raise AssertionError("decoded again instead of reading the cache")

    monkeypatch.setattr(bev_module, "decode_images", fail)
    again = render_views(bev_source(bev_root), "00", None, np.arange(0, 40, 4), {"c": None})["c", "topview"]
    np.testing.assert_array_equal(views, again)
    (bev_root / "00" / "imgs" / "000003.png").touch()  # a changed file is a new key: decoded again
    with pytest.raises(AssertionError, match="decoded again"):
        bev_source(bev_root).images("00")


def _corrupt(root: Path, how: str) -> str:
    """Break the folder one way; return what the error must name."""
    from PIL import Image

    seq = root / "00"
    if how == "no imgs":
        for p in (seq / "imgs").iterdir():
            p.unlink()
        (seq / "imgs").rmdir()
        return str(seq / "imgs")
    if how == "no pose":
        (seq / "pose.txt").unlink()
        return str(seq / "pose.txt")
    if how == "count":
        lines = (seq / "pose.txt").read_text().splitlines()
        (seq / "pose.txt").write_text("\n".join(lines[:-1]) + "\n")
        return "39 pose lines for 40 images"
    if how == "pose numbers":
        lines = (seq / "pose.txt").read_text().splitlines()
        lines[3] = " ".join(lines[3].split()[:11])
        (seq / "pose.txt").write_text("\n".join(lines) + "\n")
        return "pose.txt line 4: expected 12 numbers, got 11"
    if how == "pose nan":
        lines = (seq / "pose.txt").read_text().splitlines()
        lines[5] = lines[5].replace(lines[5].split()[3], "nan", 1)
        (seq / "pose.txt").write_text("\n".join(lines) + "\n")
        return "pose.txt line 6: contains NaN or inf"
    path = seq / "imgs" / "000007.png"
    if how == "truncated":
        path.write_bytes(path.read_bytes()[:40])
    elif how == "not png":
        Image.fromarray(np.zeros((41, 41), np.uint8), mode="L").save(path, format="JPEG")
    elif how == "size":
        Image.fromarray(np.zeros((33, 33), np.uint8), mode="L").save(path)
        return "000007.png: image is 33x33, but 000000.png is 41x41"
    elif how == "square":
        Image.fromarray(np.zeros((41, 39), np.uint8), mode="L").save(path)
        return "000007.png: image is 39x41, not square"
    return str(path)


@pytest.mark.parametrize("how", ["no imgs", "no pose", "count", "pose numbers", "pose nan", "truncated",
                                 "not png", "size", "square"])
def test_bad_input_is_one_line_naming_the_file(bev_root: Path, safl_home: Path, how: str) -> None:
    needle = _corrupt(bev_root, how)
    with pytest.raises(DataError) as info:
        source = bev_source(bev_root)
        render_views(source, "00", None, np.arange(40), {"c": None})
    message = str(info.value)
    assert needle in message and "\n" not in message


def test_cli_bad_input_exits_2_and_keeps_other_records(bev_root: Path, safl_home: Path, tmp_path: Path,
                                                       tiny_bev_tasks, capsys) -> None:
    results = tmp_path / "results"
    argv = ["run", "--method", "sad", "--quiet", "--results", str(results), "--task", REVISIT]
    assert cli_main([*argv, "--bev-root", str(bev_root)]) == 0
    kept = next(results.rglob("seed-0.json")).read_bytes()
    _corrupt(bev_root, "truncated")
    capsys.readouterr()
    assert cli_main([*argv, "--task", RANGES, "--bev-root", str(bev_root)]) == 2
    err = capsys.readouterr().err
    assert "000007.png: not a readable PNG image" in err
    assert next(results.rglob("seed-0.json")).read_bytes() == kept  # nothing computed is lost
    assert cli_main([*argv, "--bev-root", str(bev_root), "--kitti-root", str(tmp_path)]) == 2
    assert "--kitti-root and --bev-root name two data sources" in capsys.readouterr().err


def test_a_bev_task_without_its_root_says_how_to_give_it(tiny_bev_tasks, monkeypatch, capsys,
                                                         tmp_path: Path) -> None:
    monkeypatch.delenv("SAFL_BEV_ROOT", raising=False)
    with pytest.raises(DataError, match=r"needs its data: pass --bev-root DIR or set SAFL_BEV_ROOT"):
        tasks.make(REVISIT)
    code = cli_main(["run", "--method", "sad", "--quiet", "--results", str(tmp_path), "--task", REVISIT])
    assert code == 2 and "--bev-root DIR or set SAFL_BEV_ROOT" in capsys.readouterr().err


def test_point_methods_get_one_line_on_an_image_source(bev_root, safl_home, tmp_path, tiny_bev_tasks,
                                                       capsys) -> None:
    code = cli_main(["run", "--method", "scan_context", "--quiet", "--results", str(tmp_path),
                     "--bev-root", str(bev_root), "--task", REVISIT])
    err = capsys.readouterr().err
    assert code == 2
    assert "KITTI top-view images at" in err and "has no points views" in err
    assert "Traceback" not in err


def test_tasks_on_the_images_and_their_records(bev_root, safl_home, tmp_path, tiny_bev_tasks) -> None:
    ranged = tasks.make(RANGES, bev_root=str(bev_root), progress=False)
    np.testing.assert_array_equal(ranged.database_frames, np.arange(20))
    np.testing.assert_array_equal(ranged.query_frames, np.arange(20, 40))
    assert ranged.queries().shape == (20, 41, 41)
    assert not np.array_equal(ranged.queries(), ranged.database())
    assert ranged.truth.has_loop.all()  # the way back passes every place of the way out

    paper = tasks.make(PAPER, bev_root=str(bev_root), progress=False)
    expected = move_viewpoint(bev_source(bev_root).images("00")[paper.query_frames],
                              paper.query_offsets, 0.4).astype(np.float32) / 255
    np.testing.assert_array_equal(paper.queries(), expected)

    results = tmp_path / "results"
    code = cli_main(["run", "--method", "stable_afl@1", "--quiet", "--results", str(results),
                     "--bev-root", str(bev_root), "--task", RANGES, "--weights", "untrained"])
    assert code == 0
    record = json.loads(next(results.rglob("seed-0.json")).read_text())
    single = record["results"]["single_frame"]["metrics"]
    assert 0.0 <= single["recall_at_1"] <= 1.0
    assert single["recall_at_n"]["1"] == single["recall_at_1"]
    assert single["recall_at_n"]["1"] <= single["recall_at_n"]["5"] <= single["recall_at_n"]["10"]
    spec = record["task"]["spec"]
    assert spec["method_input"] == "41x41 views resampled to 64x64 (bilinear, antialiased)"
    assert spec["data_notes"][0].startswith("top views: the images of")
    assert record["task"]["protocol"] == "bevplace" and record["task"]["source_kind"] == "bev"


def test_bevplace_tasks_are_registered_with_its_ranges() -> None:
    spec = tasks.spec("SAFL/BEVKITTI02-BEVPlace-v1")
    assert (spec.database_frames, spec.query_frames, spec.tp_radius_m, spec.step) == (
        (0, 3400), (3600, 4661), 5.0, 1)
    assert tasks.suite("bev-bevplace") == [f"SAFL/BEVKITTI{s}-BEVPlace-v1" for s in ("00", "02", "05", "06")]
    assert tasks.suite("bev-paper", source="synth") == tasks.suite("bev-paper")  # source-specific suite
    assert "resampled to the moved viewpoint" in tasks.spec("SAFL/BEVKITTI00-T20R2-v1").description
    with pytest.raises(ConfigError, match="frame ranges belong to the bevplace protocol only"):
        tasks.TaskSpec(id="Test/X-v0", source="bev", sequence="00", database_frames=(0, 3))


def test_move_viewpoint_matches_the_renderers_offsets() -> None:
    image = np.zeros((1, 21, 21), np.uint8)
    image[0, 5, 10] = 200  # 5 px (2 m at 0.4 m/px) ahead of the sensor at (10, 10)
    ahead = move_viewpoint(image, np.array([[0.8, 0.0, 0.0]]), 0.4)  # drive 2 px forward
    assert ahead[0, 7, 10] == 200 and ahead.sum() == 200
    left = move_viewpoint(image, np.array([[0.0, 0.0, np.pi / 2]]), 0.4)  # turn left 90 degrees
    assert left[0, 10, 15] == 200  # what was ahead is now to the right
    assert coverage(20, np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0]]), 0.4).tolist() == [1.0, 0.5]


@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
def test_move_viewpoint_is_bit_identical_to_scipys_per_image_transform(dtype) -> None:
    """The stacked kernel reproduces scipy's affine_transform(order=0, constant 0) image by image,
    so queries (and records) made with the per-image loop are made again exactly."""
    from scipy.ndimage import affine_transform

    from safl_bench.views.resample import _affine

    rng = np.random.default_rng(3)
    n, size = 64, 31
    images = rng.integers(1, 256, (n, size, size)).astype(dtype)
    offsets = np.c_[rng.uniform(-8.0, 8.0, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    offsets[:4] = 0.0  # no move
    offsets[4:8, 2] = [np.pi / 2, -np.pi / 2, np.pi, 0.0]  # exact turns, pixel-grid points
    offsets[8:12, :2] = np.round(offsets[8:12, :2] / 0.4) * 0.4  # whole-pixel shifts
    expected = np.empty_like(images)
    for i in range(n):
        matrix, shift = _affine(size, offsets[i], 0.4)
        affine_transform(images[i], matrix, offset=shift, output=expected[i], order=0,
                         mode="constant", cval=0)
    moved = move_viewpoint(images, offsets, 0.4)
    assert moved.dtype == images.dtype
    np.testing.assert_array_equal(moved, expected)
    assert (moved == 0).any() and (moved != 0).any()
    assert move_viewpoint(images[:0], offsets[:0], 0.4).shape == (0, size, size)


def test_fit_input_resamples_only_other_sizes() -> None:
    maps = np.random.default_rng(0).random((3, 151, 151)).astype(np.float32)
    assert fit_input(maps, None) is maps and fit_input(maps, 151) is maps
    small = fit_input(maps, 64)
    assert small.shape == (3, 64, 64) and 0.0 <= small.min() and small.max() <= 1.0
    assert abs(float(small.mean()) - float(maps.mean())) < 1e-3


def _write_kitti_ground_truth(seq: Path, lidar: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """KITTI's files for LiDAR poses `lidar` moved by `shift` (m, per frame): camera poses
    Tr L inv(Tr) and a calib.txt with a non-trivial Tr; returns the LiDAR poses written."""
    tr = np.eye(4)
    tr[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]  # LiDAR x forward -> camera z forward
    tr[:3, 3] = [0.1, -0.2, 0.3]
    moved = lidar.copy()
    moved[:, :2, 3] += shift
    camera = tr @ moved @ np.linalg.inv(tr)
    (seq / "kitti_poses.txt").write_text(
        "".join(" ".join(f"{v:.12e}" for v in p[:3].ravel()) + "\n" for p in camera))
    (seq / "calib.txt").write_text(
        "P0: " + " ".join(["0"] * 12) + "\nTr: " + " ".join(f"{v:.12e}" for v in tr[:3].ravel())
        + "\n")
    return moved


def test_kitti_ground_truth_in_a_bev_root_wins_over_pose_txt(tmp_path: Path) -> None:
    root = write_bev(tmp_path / "bev", n=20)
    plain = bev_source(root)
    before = plain.sequence("00")
    shift = np.zeros((20, 2))
    shift[5:9] = [0.7, -0.4]  # as BEVPlace's 00 differs from KITTI's on a stretch of frames
    moved = _write_kitti_ground_truth(root / "00", before.poses, shift)
    after = bev_source(root).sequence("00")
    assert after.pose_file == "kitti_poses.txt"
    np.testing.assert_allclose(after.poses, moved, atol=1e-9)
    np.testing.assert_allclose(after.positions - before.positions, shift, atol=1e-9)
    notes = bev_source(root).notes("00")
    assert any("KITTI's ground truth" in n and "not pose.txt" in n for n in notes)
    assert bev_source(root).fingerprint("00") != plain.fingerprint("00")
    (root / "00" / "calib.txt").unlink()
    with pytest.raises(DataError, match=r"kitti_poses.txt: KITTI's poses need both .* calib.txt"):
        bev_source(root).sequence("00")
