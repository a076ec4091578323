"""Ground truth from poses: loop pairs, labels of both protocols, and `safl-bench data loops`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from safl_bench.cli import main as cli_main
from safl_bench.errors import ConfigError, DataError
from safl_bench.groundtruth import (
    EXCLUDED,
    FP,
    TP,
    GroundTruth,
    camera_ground_positions,
    default_times,
    loop_pairs,
    read_poses,
)

LAP = 160  # frames per lap of a 40 m x 40 m square, 1 m apart


def square(s: np.ndarray) -> np.ndarray:
    """Point at arc length s (m) along a 40 m square, counter-clockwise from (0, 0)."""
    s = np.mod(s, LAP)
    side, t = s // 40, s % 40
    x = np.select([side == 0, side == 1, side == 2], [t, 40 + 0 * t, 40 - t], 0 * t)
    y = np.select([side == 0, side == 1, side == 2], [0 * t, t, 40 + 0 * t], 40 - t)
    return np.stack([x, y], axis=1).astype(np.float64)


def loop_twice() -> np.ndarray:
    """The square driven forwards (frames 0..159), then backwards from the start (160..319)."""
    k = np.arange(LAP)
    return np.concatenate([square(k), square(-k)])


def expected_pairs(min_gap_frames: int) -> set[tuple[int, int]]:
    """Frame 160+k stands where frame (160-k) % 160 stood; 0.1 s per frame."""
    out = set()
    for k in range(LAP):
        j = (LAP - k) % LAP
        if LAP + k - j > min_gap_frames:
            out.add((LAP + k, j))
    return out


def test_loop_pairs_of_a_loop_driven_twice_once_reversed() -> None:
    pos = loop_twice()
    times = default_times(len(pos))
    pairs = loop_pairs(pos, times, radius=0.5, min_gap_s=5.0)
    got = {(int(q), int(m)) for q, m in pairs}
    assert got == expected_pairs(50)
    # frame 185 stands where 135 stood, exactly 5.0 s earlier: not "more than" 5 s
    assert (185, 135) not in got and (186, 134) in got
    assert pairs.dtype == np.int64 and np.all(np.diff(pairs[:, 0]) >= 0)


def test_loop_pairs_equal_brute_force() -> None:
    rng = np.random.default_rng(3)
    pos = loop_twice() + rng.normal(0, 0.3, size=(2 * LAP, 2))
    times = np.cumsum(rng.uniform(0.05, 0.15, size=2 * LAP))
    d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
    gap = times[:, None] - times[None, :]
    want = {(int(i), int(j)) for i, j in zip(*np.nonzero((d <= 2.5) & (gap > 3.0)), strict=True)}
    got = {(int(q), int(m)) for q, m in loop_pairs(pos, times, 2.5, 3.0)}
    assert got == want and len(want) > 100


def test_loop_pairs_reject_bad_values() -> None:
    pos = loop_twice()
    with pytest.raises(ConfigError, match="radius"):
        loop_pairs(pos, default_times(len(pos)), -1.0, 1.0)
    with pytest.raises(ConfigError, match="gap"):
        loop_pairs(pos, default_times(len(pos)), 1.0, float("nan"))
    with pytest.raises(ConfigError):
        loop_pairs(pos, default_times(3), 1.0, 1.0)


def test_paper_ground_truth_labels_within_10_m() -> None:
    pos = square(np.arange(0, LAP, 4.0))
    gt = GroundTruth(pos, pos, default_times(40), default_times(40), 10.0, 10.0, None)
    assert gt.has_loop.all()
    assert gt.db_limit().tolist() == [40] * 40
    match = np.arange(40)
    assert (gt.labels(match) == TP).all()
    # 2 frames on = 8 m away (TP); 3 frames on = 12 m (FP), except across a corner
    assert gt.label_of(0, 2) == TP and gt.label_of(0, 3) == FP
    assert set(gt.true_matches(0).tolist()) == {0, 1, 2, 38, 39}


def test_revisit_ground_truth_window_and_band() -> None:
    pos = loop_twice()
    times = default_times(len(pos))
    gt = GroundTruth(pos, pos, times, times, 3.0, 20.0, window_s=5.0)
    # candidates: strictly more than 5 s (50 frames) older
    limit = gt.db_limit()
    assert limit[50] == 0 and limit[51] == 1 and limit[319] == 269
    assert gt.label_of(200, 120) == TP  # same place, 8 s earlier
    assert gt.label_of(200, 125) == EXCLUDED  # 5 m away: in the band
    assert gt.label_of(200, 100) == EXCLUDED  # exactly 20 m: not beyond
    assert gt.label_of(200, 95) == FP  # 25 m
    assert gt.label_of(200, 199) == FP  # the same place 0.1 s earlier is not a candidate
    pairs = {(int(q), int(m)) for q, m in gt.pairs()}
    assert pairs == {(q, m) for q, m in map(tuple, loop_pairs(pos, times, 3.0, 5.0).tolist())}
    # lap 1 only meets its own start again at its end; lap 2 passes frame 0's place at once,
    # then lap 1's frames at least 5 s older from frame 184 on (3 m = 3 frames of slack)
    assert not gt.has_loop[:150].any() and gt.has_loop[159]
    assert gt.has_loop[160:164].all() and not gt.has_loop[164:184].any() and gt.has_loop[184:].all()


def test_ground_truth_rejects_bad_input() -> None:
    pos = square(np.arange(4.0))
    t = default_times(4)
    with pytest.raises(ConfigError, match="below"):
        GroundTruth(pos, pos, t, t, 5.0, 3.0)
    with pytest.raises(ConfigError):
        GroundTruth(pos, pos[:2], t, t, 5.0, 5.0)
    gt = GroundTruth(pos, pos, t, t, 5.0, 5.0)
    with pytest.raises(ConfigError, match="match indices"):
        gt.labels(np.array([0, 1, 2, 4]))


def write_camera_poses(path: Path, pos: np.ndarray) -> None:
    """KITTI camera-frame poses: ground plane = camera x, z; identity rotation."""
    lines = [f"1 0 0 {x:.6f} 0 1 0 -0.5 0 0 1 {z:.6f}" for x, z in pos]
    path.write_text("\n".join(lines) + "\n")


def test_camera_ground_positions_are_x_and_z(tmp_path: Path) -> None:
    pos = loop_twice()
    write_camera_poses(tmp_path / "00.txt", pos)
    poses = read_poses(tmp_path / "00.txt")
    assert poses.shape == (2 * LAP, 4, 4)
    np.testing.assert_allclose(camera_ground_positions(poses), pos, atol=1e-6)


def test_data_loops_cli_writes_expected_pairs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_camera_poses(tmp_path / "poses.txt", loop_twice())
    out = tmp_path / "out" / "loops.csv"
    rc = cli_main(
        [
            "data",
            "loops",
            "--poses",
            str(tmp_path / "poses.txt"),
            "--radius",
            "0.5",
            "--min-gap-s",
            "5",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    lines = out.read_text().splitlines()
    assert lines[0] == "query,match"
    got = {tuple(int(v) for v in line.split(",")) for line in lines[1:]}
    assert got == expected_pairs(50) and len(lines) - 1 == len(got)
    assert "135 loop pairs" in capsys.readouterr().out
    # with times.txt: frames 1 s apart, so a 5 s gap is 5 frames
    (tmp_path / "times.txt").write_text("\n".join(f"{i:.1f}" for i in range(2 * LAP)) + "\n")
    rc = cli_main(
        [
            "data",
            "loops",
            "--poses",
            str(tmp_path / "poses.txt"),
            "--times",
            str(tmp_path / "times.txt"),
            "--radius",
            "0.5",
            "--min-gap-s",
            "5",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    got = {tuple(int(v) for v in line.split(",")) for line in out.read_text().splitlines()[1:]}
    assert got == expected_pairs(5)


@pytest.mark.parametrize(
    ("case", "needle"),
    [
        ("bad_line", "line 3"),
        ("short_times", "times.txt"),
        ("negative_radius", "--radius"),
        ("missing", "nope.txt"),
    ],
)
def test_data_loops_cli_bad_input_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str, needle: str
) -> None:
    poses = tmp_path / "poses.txt"
    write_camera_poses(poses, loop_twice()[:10])
    args = ["--radius", "2", "--min-gap-s", "1"]
    if case == "bad_line":
        text = poses.read_text().splitlines()
        text[2] = "1 0 0 oops"
        poses.write_text("\n".join(text))
    elif case == "short_times":
        (tmp_path / "times.txt").write_text("0.0\n0.1\n")
        args += ["--times", str(tmp_path / "times.txt")]
    elif case == "negative_radius":
        args = ["--radius", "-2", "--min-gap-s", "1"]
    else:
        poses = tmp_path / "nope.txt"
    rc = cli_main(["data", "loops", "--poses", str(poses), *args, "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and needle in err and "Traceback" not in err
    assert not (tmp_path / "o.csv").exists()


def test_read_poses_rejects_malformed_file(tmp_path: Path) -> None:
    path = tmp_path / "p.txt"
    path.write_text("1 2 3\n")
    with pytest.raises(DataError, match=r"p\.txt"):
        read_poses(path)
    path.write_text("\n\n")
    with pytest.raises(DataError, match="no poses"):
        read_poses(path)
