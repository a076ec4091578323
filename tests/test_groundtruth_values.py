"""Exact values of `safl_bench.groundtruth` on small hand-made layouts: radii and windows at
their boundaries, the band, candidates, empty sides, and the poses and times readers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from safl_bench.errors import ConfigError, DataError
from safl_bench.groundtruth import (
    DEFAULT_PERIOD_S,
    EXCLUDED,
    FP,
    TP,
    GroundTruth,
    camera_ground_positions,
    default_times,
    loop_pairs,
    read_poses,
    read_times,
)


def line(xs: list[float]) -> np.ndarray:
    return np.c_[np.asarray(xs, float), np.zeros(len(xs))]


def test_labels_at_the_radii_and_the_band() -> None:
    # database at x = 0; queries at 3 (on the tp radius), 3.5, 20 (on the fp radius), 20.5, and
    # one at (3, 4): 5 m in the plane (hypot, not a sum or a single axis)
    q = np.array([[3.0, 0], [3.5, 0], [20.0, 0], [20.5, 0], [3.0, 4.0], [0.0, -2.9]])
    gt = GroundTruth(q, np.zeros((1, 2)), np.zeros(6), np.zeros(1), 3.0, 20.0)
    assert gt.labels(np.zeros(6, int)).tolist() == [TP, EXCLUDED, EXCLUDED, FP, EXCLUDED, TP]
    assert gt.labels(np.zeros(6, int)).dtype == np.int8
    np.testing.assert_allclose(gt.distances(np.arange(6), 0), [3, 3.5, 20, 20.5, 5, 2.9])
    assert gt.has_loop.tolist() == [True, False, False, False, False, True]
    assert gt.pairs().tolist() == [[0, 0], [5, 0]]
    assert gt.true_matches(0).tolist() == [0] and gt.true_matches(1).tolist() == []
    assert (gt.n_queries, gt.n_database) == (6, 1)


def test_the_window_is_strict_and_candidates_are_a_prefix() -> None:
    # database frames at t = 0, 1, 2, 3; queries at t = 2.5, 3, 3.5, 10; window 1 s
    db = line([0, 1, 2, 3])
    q = line([0, 1, 2, 3])
    gt = GroundTruth(q, db, np.array([2.5, 3.0, 3.5, 10.0]), np.arange(4.0), 1.0, 1.0,
                     window_s=1.0)
    # t_q - t_db > 1: 2.5 -> {0, 1}; 3 -> {0, 1} (2 is exactly 1 s older: not a candidate)
    assert gt.db_limit().tolist() == [2, 2, 3, 4]
    np.testing.assert_array_equal(gt.candidate_mask(), np.arange(4)[None, :] < [[2], [2], [3], [4]])
    assert gt.is_candidate(1, 1).item() and not gt.is_candidate(1, 2).item()
    assert gt.is_candidate(np.array([0, 3]), np.array([2, 3])).tolist() == [False, True]
    assert gt.has_candidate.tolist() == [True, True, True, True]
    # true places: candidates within 1 m (q2 at x = 2, t = 3.5: frames 0-2 are candidates)
    assert [gt.true_matches(i).tolist() for i in range(4)] == [[0, 1], [0, 1], [1, 2], [2, 3]]
    assert gt.has_loop.all()
    # a non-candidate answer is FP at any distance, a candidate in reach TP
    assert gt.label_of(1, 1) == TP and gt.label_of(0, 2) == FP and gt.label_of(3, 3) == TP


def test_queries_younger_than_the_window_have_no_candidate() -> None:
    t = np.arange(5.0)
    gt = GroundTruth(line([0] * 5), line([0] * 5), t, t, 1.0, 1.0, window_s=2.0)
    assert gt.has_candidate.tolist() == [False, False, False, True, True]
    assert gt.db_limit().tolist() == [0, 0, 0, 1, 2]
    assert gt.has_loop.tolist() == [False, False, False, True, True]
    # a window of 0 s still needs a strictly older frame
    zero = GroundTruth(line([0] * 3), line([0] * 3), np.arange(3.0), np.arange(3.0), 1.0, 1.0,
                       window_s=0.0)
    assert zero.has_candidate.tolist() == [False, True, True]
    assert zero.db_limit().tolist() == [0, 1, 2]


def test_paper_protocol_makes_every_frame_a_candidate() -> None:
    t = np.arange(3.0)
    gt = GroundTruth(line([0, 50, 100]), line([100, 0]), t, t[:2], 10.0, 10.0)
    assert gt.candidate_mask().tolist() == [[True, True]] * 3
    assert gt.candidate_mask().dtype == bool
    assert gt.is_candidate(np.array([0, 1]), 1).tolist() == [True, True]
    assert gt.is_candidate(0, np.array([0, 1])).tolist() == [True, True]
    assert gt.is_candidate(np.array([[0], [2]]), np.array([0, 1])).shape == (2, 2)
    assert gt.db_limit().tolist() == [2, 2, 2] and gt.db_limit().dtype == np.int64
    assert gt.has_candidate.tolist() == [True, True, True]
    assert [gt.true_matches(i).tolist() for i in range(3)] == [[1], [], [0]]
    assert gt.pairs().tolist() == [[0, 1], [2, 0]] and gt.pairs().dtype == np.int64


def test_true_matches_are_sorted() -> None:
    db = line([5, 1, 3, 50, 2])
    gt = GroundTruth(line([2]), db, np.zeros(1), np.zeros(5), 3.0, 3.0)
    assert gt.true_matches(0).tolist() == [0, 1, 2, 4]
    assert gt.true_matches(0).dtype == np.int64


def test_an_empty_database_or_query_side() -> None:
    gt = GroundTruth(line([0, 1]), np.zeros((0, 2)), np.zeros(2), np.zeros(0), 1.0, 1.0)
    assert gt.has_candidate.tolist() == [False, False] and gt.has_loop.tolist() == [False, False]
    assert gt.pairs().shape == (0, 2)
    none = GroundTruth(np.zeros((0, 2)), line([0]), np.zeros(0), np.zeros(1), 1.0, 1.0)
    assert none.pairs().shape == (0, 2) and none.pairs().dtype == np.int64
    assert none.labels(np.zeros(0, int)).tolist() == []


def test_candidates_that_are_not_a_prefix_are_refused() -> None:
    # database not in time order: frame 0 is younger than frame 1
    gt = GroundTruth(line([0]), line([0, 0]), np.array([10.0]), np.array([9.5, 1.0]), 1.0, 1.0,
                     window_s=2.0)
    with pytest.raises(ConfigError, match=r"^the candidates of some query are not a prefix"):
        gt.db_limit()


def test_ground_truth_checks() -> None:
    xy, t = line([0, 1]), np.zeros(2)
    for name, kw in [("true-positive radius", dict(tp_radius=-1.0, fp_radius=1.0)),
                     ("true-positive radius", dict(tp_radius=np.inf, fp_radius=np.inf)),
                     ("false-positive radius", dict(tp_radius=1.0, fp_radius=np.nan))]:
        with pytest.raises(ConfigError, match=rf"^{name} must be a finite distance >= 0 m"):
            GroundTruth(xy, xy, t, t, **kw)
    with pytest.raises(ConfigError, match=r"^false-positive radius 2.0 m is below the "
                                          r"true-positive radius 3.0 m$"):
        GroundTruth(xy, xy, t, t, 3.0, 2.0)
    for window in (-0.1, np.inf, np.nan):
        with pytest.raises(ConfigError, match=r"^time window must be a finite number"):
            GroundTruth(xy, xy, t, t, 1.0, 1.0, window_s=window)
    with pytest.raises(ConfigError, match=r"^ground truth needs \(n, 2\) positions"):
        GroundTruth(np.zeros((2, 3)), xy, t, t, 1.0, 1.0)
    with pytest.raises(ConfigError, match=r"^ground truth needs \(n, 2\) positions"):
        GroundTruth(xy, xy, t, t[:1], 1.0, 1.0)
    with pytest.raises(ConfigError, match=r"^ground truth needs \(n, 2\) positions"):
        GroundTruth(xy, xy, t[:1], t, 1.0, 1.0)
    with pytest.raises(ConfigError, match=r"^ground truth needs \(n, 2\) positions"):
        GroundTruth(xy, np.zeros((2, 1)), t, t, 1.0, 1.0)
    # zero radii are allowed; equal radii (no band) too
    gt = GroundTruth(xy, xy, [0, 1], [0, 1], 0.0, 0.0)
    assert gt.query_times.dtype == np.float64 and gt.database_positions.dtype == np.float64
    assert [gt.true_matches(i).tolist() for i in range(2)] == [[0], [1]]
    assert gt.labels(np.array([1, 1])).tolist() == [FP, TP]


def test_labels_checks() -> None:
    gt = GroundTruth(line([0, 1]), line([0, 1, 2]), np.zeros(2), np.zeros(3), 1.0, 1.0)
    with pytest.raises(ConfigError, match=r"^need one match per query \(2\), got shape \(3,\)$"):
        gt.labels(np.array([0, 1, 2]))
    with pytest.raises(ConfigError, match=r"^match indices must lie in \[0, 3\), got -1\.\.1$"):
        gt.labels(np.array([-1, 1]))
    with pytest.raises(ConfigError, match=r"^match indices must lie in \[0, 3\), got 0\.\.3$"):
        gt.labels(np.array([0, 3]))
    assert gt.labels(np.array([2, 0])).tolist() == [FP, TP]  # 2 m, 1 m
    assert gt.labels(np.array([2.0, 0.0])).tolist() == [FP, TP]  # frame numbers as floats
    assert gt.labels([1, 1]).tolist() == [TP, TP]


def test_loop_pairs_at_the_boundaries() -> None:
    pos = line([0, 1, 2, 0, 1.5])
    times = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    # within 1 m and more than 2 s older
    got = loop_pairs(pos, times, 1.0, 2.0).tolist()
    assert got == [[3, 0], [4, 1]]  # (3, 1) and (4, 2) are exactly 2 s apart: not more
    assert loop_pairs(pos, times, 1.0, 2.0).dtype == np.int64
    # unsigned stamps (frame numbers) are times like any other: no wrap-around when subtracting
    assert loop_pairs(pos, np.arange(5, dtype=np.uint8), 1.0, 2.0).tolist() == [[3, 0], [4, 1]]
    # time running backwards: the younger frame is the query whatever the order of the frames
    assert loop_pairs(pos, times[::-1], 1.0, 2.0).tolist() == [[0, 3], [1, 4]]
    # sorted by query, then by match
    assert loop_pairs(line([0, 5, 9, 5, 0]), times, 1.0, 1.0).tolist() == [[3, 1], [4, 0]]
    assert loop_pairs(line([0, 0, 9, 0]), times[:4], 1.0, 0.5).tolist() == [[1, 0], [3, 0],
                                                                           [3, 1]]
    assert loop_pairs(pos, times, 0.4, 0.0).tolist() == [[3, 0]]
    assert loop_pairs(pos, times, 10.0, 0.0).shape == (10, 2)
    assert loop_pairs(line([0, 100]), times[:2], 1.0, 0.0).shape == (0, 2)
    with pytest.raises(ConfigError, match=r"^radius must be a finite distance"):
        loop_pairs(pos, times, np.inf, 0.0)
    with pytest.raises(ConfigError, match=r"^minimum time gap must be a finite number"):
        loop_pairs(pos, times, 1.0, -1.0)
    with pytest.raises(ConfigError, match=r"^minimum time gap must be a finite number"):
        loop_pairs(pos, times, 1.0, np.inf)
    with pytest.raises(ConfigError, match=r"^need \(n, 2\) positions and n times"):
        loop_pairs(np.zeros((5, 3)), times, 1.0, 0.0)
    with pytest.raises(ConfigError, match=r"^need \(n, 2\) positions and n times"):
        loop_pairs(np.zeros(5), times, 1.0, 0.0)


def test_default_times_are_exact_decimals() -> None:
    t = default_times(4)
    assert t.tolist() == [0.0, 0.1, 0.2, 0.3] and t.dtype == np.float64
    assert DEFAULT_PERIOD_S == 0.1
    assert default_times(3, 0.5).tolist() == [0.0, 0.5, 1.0]
    assert default_times(31)[30] == 3.0  # not 3.0000000000000004 (30 * 0.1)


def test_camera_ground_positions_take_x_and_z() -> None:
    poses = np.tile(np.eye(4), (2, 1, 1))
    poses[:, :3, 3] = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    out = camera_ground_positions(poses)
    assert out.tolist() == [[1.0, 3.0], [4.0, 6.0]] and out.flags.c_contiguous
    assert camera_ground_positions(poses[:, :3]).tolist() == [[1.0, 3.0], [4.0, 6.0]]
    assert camera_ground_positions(poses.astype(np.float32)).dtype == np.float64


def test_read_poses_and_times(tmp_path: Path) -> None:
    path = tmp_path / "p.txt"
    pose = "1 0 0 {x} 0 1 0 0 0 0 1 {z}"
    path.write_text(pose.format(x=1, z=2) + "\n\n  \n" + pose.format(x=3, z=4) + "\n")
    poses = read_poses(str(path))  # blank lines are not poses
    assert poses.shape == (2, 4, 4) and camera_ground_positions(poses).tolist() == [[1, 2], [3, 4]]
    with pytest.raises(DataError, match="does not exist or is not a file"):
        read_poses(tmp_path / "missing.txt")
    with pytest.raises(DataError, match="does not exist or is not a file"):
        read_poses(tmp_path)
    path.write_bytes(b"\xff\xfe\x00bad")
    with pytest.raises(DataError, match=r"not a text file \("):
        read_poses(path)
    times = tmp_path / "times.txt"
    times.write_text("0.0\n0.5\n")
    assert read_times(str(times), 2).tolist() == [0.0, 0.5]
    with pytest.raises(DataError, match="2 timestamps for 3 scans"):
        read_times(times, 3)
