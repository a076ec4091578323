"""The label layer and one cell's evaluation: which answers count as what, the positives fixed
by the ground truth, queries without a candidate, and one tie rule for matcher and Recall@N."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_evaluation_values import MatrixMethod  # one stand-in method for both files

from safl_bench.evaluation import EvaluationConfig, evaluate_method, match_outcomes, score_matches
from safl_bench.groundtruth import GroundTruth
from safl_bench.matching import MatcherConfig, match, single_frame
from safl_bench.metrics import AMBIGUOUS, CORRECT, WRONG, NoPositivesError


def revisit_truth() -> GroundTruth:
    """Frames 0-4 drive x = 0..40 m; frames 5-9 come back 31 s later at x + (1, 2, 5, 30, 0).
    With a 30 s window only frames 0-4 are candidates of 5-9; 0-4 have none."""
    x = np.r_[np.arange(5) * 10.0, np.arange(5) * 10.0 + [1, 2, 5, 30, 0]]
    xy = np.c_[x, np.zeros(10)]
    t = np.r_[np.arange(5.0), np.arange(5.0) + 36.0]
    return GroundTruth(xy, xy, t, t, tp_radius=3.0, fp_radius=20.0, window_s=30.0)


def result_of(index: list[int], confidence: list[float]) -> Any:
    D = np.ones((10, 10))
    res = single_frame(D)
    res.index = np.array(index)
    res.score = -np.array(confidence, dtype=np.float64)
    return res


def test_labels_of_the_revisit_protocol_by_hand() -> None:
    truth = revisit_truth()
    assert truth.has_candidate.tolist() == [False] * 5 + [True] * 5
    # 5->0: 1 m (correct), 6->1: 2 m (correct), 7->2: 5 m (band), 8->0: 60 m (wrong), 9->4: 0 m
    index = [-1, -1, -1, -1, -1, 0, 1, 2, 0, 4]
    conf = [-np.inf] * 5 + [0.9, 0.8, 0.7, 0.95, 0.6]
    o = match_outcomes(truth, result_of(index, conf))
    assert o.label[5:].tolist() == [CORRECT, CORRECT, AMBIGUOUS, WRONG, CORRECT]
    assert o.has_true_place.tolist() == [False] * 5 + [True, True, False, False, True]
    m = score_matches(truth, result_of(index, conf))
    assert (m.n_scored, m.n_positive, m.n_correct, m.n_ambiguous) == (5, 3, 3, 1)
    assert m.recall_at_100 == 0.0  # 8->0 (60 m, wrong) is the most confident
    assert m.recall_at_1 == 1.0
    assert m.roc_auc == pytest.approx(0.0)  # the one wrong match outranks the three correct


def test_an_answer_the_query_may_not_give_is_wrong_whatever_its_distance() -> None:
    truth = revisit_truth()
    index = [-1, -1, -1, -1, -1, 5, 1, 2, 3, 4]  # 5 answers itself: not older than the window
    conf = [-np.inf] * 5 + [0.9, 0.8, 0.7, 0.6, 0.5]
    o = match_outcomes(truth, result_of(index, conf))
    assert o.label[5] == WRONG


def test_the_positives_are_the_same_whatever_the_wrong_answers() -> None:
    truth = revisit_truth()
    conf = [-np.inf] * 5 + [0.9, 0.8, 0.7, 0.6, 0.5]
    band = score_matches(truth, result_of([-1] * 5 + [0, 1, 2, 0, 4], conf))  # 7 in the band
    far = score_matches(truth, result_of([-1] * 5 + [0, 1, 0, 0, 4], conf))  # 7 at 25 m
    assert band.n_positive == far.n_positive == 3
    assert band.recall_at_1 == far.recall_at_1
    assert band.recall_at_100 == pytest.approx(2 / 3) == far.recall_at_100


def paper_truth(n: int, spacing: float) -> GroundTruth:
    xy = np.c_[np.arange(n) * spacing, np.zeros(n)]
    t = np.arange(n, dtype=float)
    return GroundTruth(xy, xy, t, t, tp_radius=10.0, fp_radius=10.0)


@settings(max_examples=120, deadline=None)
@given(st.integers(3, 12), st.integers(3, 30), st.integers(0, 2**31 - 1), st.booleans())
def test_recall_at_1_of_recall_at_n_is_the_single_frame_recall(nq: int, ndb: int, seed: int,
                                                                near_ties: bool) -> None:
    rng = np.random.default_rng(seed)
    D = rng.integers(0, 3, (nq, ndb)).astype(np.float64)  # many exact ties
    if near_ties:
        D += rng.integers(0, 2, D.shape) * 1e-9  # ties in float32, not in float64
    q_xy = rng.uniform(0, 40, nq)
    db_xy = rng.uniform(0, 40, ndb)
    truth = GroundTruth(np.c_[q_xy, np.zeros(nq)], np.c_[db_xy, np.zeros(ndb)], np.arange(nq, dtype=float),
                        np.arange(ndb, dtype=float), tp_radius=3.0, fp_radius=3.0)
    if not truth.has_loop.any():
        return
    ev = evaluate_method(MatrixMethod(D), np.arange(nq), np.arange(ndb), truth)
    single = ev.metrics["single_frame"]
    assert single.recall_at_n[1] == single.recall_at_1
    assert single.recall_at_n[1] <= single.recall_at_n[5] <= single.recall_at_n[10]


def test_ties_go_to_the_lowest_frame_in_matcher_and_ranks() -> None:
    D = np.array([[0.5, 0.2, 0.2, 0.2], [0.3, 0.3, 0.9, 0.3]])
    res = single_frame(D)
    assert res.index.tolist() == [1, 0]
    seq = match(np.tile(D, (3, 1)), MatcherConfig(ds=0, method="single_frame", enhance_window=0))
    assert seq.index.tolist() == [1, 0] * 3
    # a true place at frame 2 of query 0 ranks behind frame 1 (equal distance, lower index)
    truth = GroundTruth(np.array([[20.0, 0], [0.0, 0]]), np.array([[0.0, 0], [100, 0], [20, 0], [200, 0]]),
                        np.zeros(2), np.zeros(4), tp_radius=1.0, fp_radius=1.0)
    ev = evaluate_method(MatrixMethod(np.r_[D, D]), np.arange(2), np.arange(4), truth)
    assert ev.outcomes["single_frame"].true_rank.tolist() == [2, 1]
    assert ev.metrics["single_frame"].recall_at_n == {1: 0.5, 5: 1.0, 10: 1.0}


def test_recall_at_n_counts_only_frames_the_query_may_match() -> None:
    truth = revisit_truth()
    # query 9 (x = 40) sits on frame 4 and on itself; only frames 0-4 are candidates
    D = np.full((10, 10), 5.0)
    D[9, 9] = 0.0  # itself: nearest, but younger than the window
    D[9, 3] = 1.0  # a wrong candidate, nearer than the true place 4
    D[9, 4] = 2.0
    ev = evaluate_method(MatrixMethod(D), np.arange(10), np.arange(10), truth, revisit=True)
    assert ev.outcomes["single_frame"].true_rank[9] == 2
    assert ev.matches["single_frame"].index[9] == 3


def test_evaluation_without_positives_raises_its_own_error() -> None:
    truth = paper_truth(4, 100.0)
    far = GroundTruth(truth.query_positions + 1000, truth.database_positions, truth.query_times,
                      truth.database_times, tp_radius=10.0, fp_radius=10.0)
    with pytest.raises(NoPositivesError):
        evaluate_method(MatrixMethod(np.ones((4, 4))), np.arange(4), np.arange(4), far)


def test_trimmed_queries_leave_the_metrics_not_the_matches() -> None:
    truth = paper_truth(12, 1.0)
    D = np.abs(np.subtract.outer(np.arange(12.0), np.arange(12.0)))
    ev = evaluate_method(MatrixMethod(D), np.arange(12), np.arange(12), truth,
                         config=EvaluationConfig(trim_queries=2))
    assert len(ev.matches["sequence"].index) == 12
    assert ev.metrics["sequence"].n_queries == 8 and ev.metrics["single_frame"].recall_at_1 == 1.0
