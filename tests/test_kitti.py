"""The KITTI reader against plain pykitti on a generated fixture, and every bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pykitti
import pytest
from conftest import lidar_poses

from safl_bench.errors import DataError
from safl_bench.sources.kitti import open_sequence


def test_reader_matches_pykitti(kitti_root: Path) -> None:
    seq = open_sequence(kitti_root, "00")
    ref = pykitti.odometry(str(kitti_root), "00")
    assert len(seq) == len(ref.velo_files) == 12
    for i in (0, 5, 11):
        scan = seq.scan(i)
        assert scan.dtype == np.float32 and scan.shape[1] == 4
        np.testing.assert_array_equal(scan, ref.get_velo(i))
    tr = ref.calib.T_cam0_velo
    expect = np.linalg.inv(tr) @ np.asarray(ref.poses) @ tr
    np.testing.assert_allclose(seq.poses, expect, atol=1e-12)
    np.testing.assert_allclose(seq.times, [t.total_seconds() for t in ref.timestamps], atol=1e-6)


def test_poses_are_lidar_frame(kitti_root: Path) -> None:
    seq = open_sequence(kitti_root, "00")
    np.testing.assert_allclose(seq.poses, lidar_poses(12), atol=1e-9)
    assert seq.positions.shape == (12, 2)
    np.testing.assert_allclose(seq.positions[1], [1.0, 0.0], atol=1e-9)
    assert seq.headings[0] == pytest.approx(0.0, abs=1e-9)
    assert seq.headings[-1] > 0.1  # the route turns left


def _bin(root: Path, i: int = 3) -> Path:
    return root / "sequences" / "00" / "velodyne" / f"{i:06d}.bin"


def test_bad_scan_size(kitti_copy: Path) -> None:
    with open(_bin(kitti_copy), "ab") as fh:
        fh.write(b"\0" * 5)
    with pytest.raises(DataError, match=r"000003\.bin.*multiple of 16"):
        open_sequence(kitti_copy, "00")


def test_empty_scan(kitti_copy: Path) -> None:
    _bin(kitti_copy).write_bytes(b"")
    with pytest.raises(DataError, match=r"000003\.bin: empty"):
        open_sequence(kitti_copy, "00")


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nonfinite_points_on_read(kitti_copy: Path, bad: float) -> None:
    pts = np.fromfile(_bin(kitti_copy), dtype=np.float32).reshape(-1, 4)
    pts[7, 1] = bad
    pts.tofile(_bin(kitti_copy))
    seq = open_sequence(kitti_copy, "00")  # values are checked when the scan is read
    seq.scan(2)
    with pytest.raises(DataError, match=r"000003\.bin: 1 of \d+ points are NaN or inf"):
        seq.scan(3)


def test_scan_index_out_of_range(kitti_root: Path) -> None:
    with pytest.raises(DataError, match="out of range"):
        open_sequence(kitti_root, "00").scan(12)


@pytest.mark.parametrize("delta", [-1, 1])
def test_pose_count_mismatch(kitti_copy: Path, delta: int) -> None:
    path = kitti_copy / "poses" / "00.txt"
    lines = path.read_text().splitlines()
    lines = lines[:-1] if delta < 0 else [*lines, lines[-1]]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=rf"00\.txt: {12 + delta} poses for 12 scans"):
        open_sequence(kitti_copy, "00")


def test_malformed_pose_line(kitti_copy: Path) -> None:
    path = kitti_copy / "poses" / "00.txt"
    lines = path.read_text().splitlines()
    lines[4] = " ".join(lines[4].split()[:11])
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"00\.txt line 5: expected 12 numbers, got 11"):
        open_sequence(kitti_copy, "00")
    lines[4] = lines[4] + " abc"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"00\.txt line 5: not a list of numbers"):
        open_sequence(kitti_copy, "00")


def test_missing_calib(kitti_copy: Path) -> None:
    (kitti_copy / "sequences" / "00" / "calib.txt").unlink()
    with pytest.raises(DataError, match=r"calib\.txt: calibration file is missing"):
        open_sequence(kitti_copy, "00")


def test_calib_without_tr(kitti_copy: Path) -> None:
    path = kitti_copy / "sequences" / "00" / "calib.txt"
    path.write_text("".join(line + "\n" for line in path.read_text().splitlines() if not line.startswith("Tr")))
    with pytest.raises(DataError, match=r"calib\.txt: no 'Tr:' line"):
        open_sequence(kitti_copy, "00")


def test_missing_sequence_lists_existing(kitti_root: Path) -> None:
    with pytest.raises(DataError, match=r"no such sequence \(sequences under .*: 00\)"):
        open_sequence(kitti_root, "07")


def test_missing_root(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="does not exist"):
        open_sequence(tmp_path / "nope", "00")


def test_missing_times(kitti_copy: Path) -> None:
    (kitti_copy / "sequences" / "00" / "times.txt").unlink()
    with pytest.raises(DataError, match=r"times\.txt: timestamps file is missing"):
        open_sequence(kitti_copy, "00")


def test_missing_poses(kitti_copy: Path) -> None:
    (kitti_copy / "poses" / "00.txt").unlink()
    with pytest.raises(DataError, match="poses are required for ground truth"):
        open_sequence(kitti_copy, "00")
    seq = open_sequence(kitti_copy, "00", require_poses=False)
    assert seq.scan(0).shape[1] == 4
    with pytest.raises(DataError, match="poses are required for ground truth"):
        _ = seq.positions


def test_cli_one_line_error(kitti_copy: Path, capsys: pytest.CaptureFixture[str], safl_home: Path) -> None:
    from safl_bench.cli import main

    (kitti_copy / "sequences" / "00" / "calib.txt").unlink()
    code = main(["data", "prepare", "--kitti-root", str(kitti_copy), "--sequences", "00"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and "calib.txt" in err
