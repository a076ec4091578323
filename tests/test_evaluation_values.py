"""Exact values of `safl_bench.evaluation` on small hand-made cases: the settings and their
records, the label layer, max_frames and trim_queries subsets, the revisit candidates, and what
describing costs."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from safl_bench import descriptor_cache, evaluation
from safl_bench.errors import ConfigError, DataError
from safl_bench.evaluation import (
    EvaluationConfig,
    evaluate_method,
    match_outcomes,
    same_settings,
    score_matches,
    scored_queries,
    subset_result,
    subset_truth,
)
from safl_bench.groundtruth import GroundTruth
from safl_bench.matching import MatcherConfig, match, single_frame
from safl_bench.metrics import AMBIGUOUS, CORRECT, WRONG, true_place_ranks


class MatrixMethod:
    """Descriptors are frame numbers; the distance is a given matrix."""

    name = "matrix"
    input_kind = "topview"
    cache_descriptors = False

    def __init__(self, D: np.ndarray) -> None:
        self.D = D
        self.calls: list[int] = []

    def describe(self, views: np.ndarray) -> np.ndarray:
        self.calls.append(len(views))
        return np.asarray(views, dtype=np.float64)[:, None]

    def distance(self, q: np.ndarray, db: np.ndarray) -> np.ndarray:
        return self.D[np.ix_(q[:, 0].astype(int), db[:, 0].astype(int))]


def line_truth(n: int, spacing: float = 1.0, tp: float = 1.0) -> GroundTruth:
    xy = np.c_[np.arange(n) * spacing, np.zeros(n)]
    t = np.arange(n, dtype=float)
    return GroundTruth(xy, xy, t, t, tp_radius=tp, fp_radius=tp)


def revisit_truth() -> GroundTruth:
    """Frames 0-4 at x = 0..40 m; 5-9 come back 31-36 s later at x + (1, 2, 5, 30, 0); 30 s
    window, 3 m / 20 m radii. Frames 0-4 have no candidate."""
    x = np.r_[np.arange(5) * 10.0, np.arange(5) * 10.0 + [1, 2, 5, 30, 0]]
    xy = np.c_[x, np.zeros(10)]
    t = np.r_[np.arange(5.0), np.arange(5.0) + 36.0]
    return GroundTruth(xy, xy, t, t, tp_radius=3.0, fp_radius=20.0, window_s=30.0)


# --------------------------------------------------------------------------- settings


@pytest.mark.parametrize("kw", [dict(max_frames=0), dict(max_frames=True), dict(max_frames=2.0),
                                dict(max_frames="3"), dict(trim_queries=-1),
                                dict(trim_queries=True), dict(trim_queries=1.0)])
def test_bad_evaluation_settings(kw: dict) -> None:
    with pytest.raises(ConfigError, match=r"^(max_frames|trim_queries) must be"):
        EvaluationConfig(**kw)


def test_good_evaluation_settings() -> None:
    assert EvaluationConfig(max_frames=1, trim_queries=0).max_frames == 1
    assert EvaluationConfig(max_frames=None).max_frames is None
    cfg = EvaluationConfig()
    assert (cfg.max_frames, cfg.trim_queries, cfg.sequence) == (None, 0, MatcherConfig())


def test_each_mode_has_its_matcher() -> None:
    cfg = EvaluationConfig(MatcherConfig(ds=4, ratio_window=6, dtype="float64", shift=False,
                                         preset="x"))
    assert cfg.matcher("sequence") is cfg.sequence
    single = cfg.matcher("single_frame")
    assert single == MatcherConfig(method="single_frame", ds=0, enhance_window=0, ratio_window=6,
                                   dtype="float64", shift=False, preset="x")
    inverse = EvaluationConfig(MatcherConfig(score="inverse", dtype="float64", preset="authors"))
    assert inverse.matcher("single_frame") == MatcherConfig(
        method="single_frame", ds=0, enhance_window=0, score="min", dtype="float64",
        preset="authors")


def test_settings_record_and_read_back() -> None:
    cfg = EvaluationConfig(MatcherConfig(ds=3), max_frames=7, trim_queries=2)
    d = cfg.to_dict()
    assert list(d) == ["sequence", "single_frame", "evaluation"]
    assert d["evaluation"] == {"max_frames": 7, "trim_queries": 2, "distance": "method",
                               "truth_at": "frame"}
    assert d["sequence"] == MatcherConfig(ds=3).to_dict()
    assert d["single_frame"] == cfg.single_frame.to_dict()
    assert EvaluationConfig.from_dict(d) == cfg
    # a record made before the evaluation-level settings existed
    old = {"sequence": MatcherConfig().to_dict()}
    assert EvaluationConfig.from_dict(old) == EvaluationConfig()
    for bad in (None, [], {"single_frame": {}}, {"sequence": 3}):
        with pytest.raises(ConfigError, match=r"^matcher settings need a 'sequence' mapping, got "):
            EvaluationConfig.from_dict(bad)  # type: ignore[arg-type]
    for bad in ({"sequence": {}, "evaluation": {"max_frames": 1, "other": 0}},
                {"sequence": {}, "evaluation": [1]}):
        with pytest.raises(ConfigError, match=r"^evaluation settings: expected keys of "
                                              r"\['max_frames', 'trim_queries', 'distance', 'truth_at', "
                                              r"'candidates', 'index'\], got "):
            EvaluationConfig.from_dict(bad)  # type: ignore[arg-type]


def test_same_settings() -> None:
    wanted = EvaluationConfig().to_dict()
    assert same_settings(wanted, wanted)
    assert same_settings({"sequence": MatcherConfig().to_dict()}, wanted)  # older record
    assert not same_settings({"sequence": MatcherConfig(ds=3).to_dict()}, wanted)
    assert not same_settings({"sequence": {"no_such": 1}}, wanted)  # ConfigError: never raises
    assert not same_settings("garbage", wanted)
    assert not same_settings({"sequence": {}, "evaluation": {"max_frames": [1]}}, wanted)


# --------------------------------------------------------------------------- label layer


def result_of(index: list[int], confidence: list[float]) -> Any:
    res = single_frame(np.ones((len(index), 10)))
    res.index = np.array(index)
    res.score = -np.array(confidence, dtype=np.float64)
    return res


def test_label_layer_by_hand() -> None:
    truth = revisit_truth()
    index = [-1, -1, -1, -1, -1, 0, 1, 2, 9, -1]  # 8 -> 9: not a candidate; 9 answers nothing
    conf = [-np.inf] * 5 + [0.9, 0.8, 0.7, 0.95, -np.inf]
    o = match_outcomes(truth, result_of(index, conf), ranks=np.array([0] * 5 + [1, 1, 0, 0, 2]))
    assert o.label.tolist() == [WRONG] * 5 + [CORRECT, CORRECT, AMBIGUOUS, WRONG, WRONG]
    assert o.has_candidate.tolist() == [False] * 5 + [True] * 5
    assert o.has_true_place.tolist() == [False] * 5 + [True, True, False, False, True]
    assert o.true_rank is not None and o.true_rank.tolist() == [0] * 5 + [1, 1, 0, 0, 2]
    np.testing.assert_array_equal(o.confidence, conf)
    m = score_matches(truth, result_of(index, conf))
    assert (m.n_scored, m.n_positive, m.n_correct, m.n_ambiguous, m.n_claimed) == (5, 3, 2, 1, 4)
    assert m.recall_at_1 == pytest.approx(2 / 3) and m.recall_at_100 == 0.0
    assert m.roc_auc == pytest.approx(0.5)  # wrong .95 > correct .9, .8 > unanswered 9


def test_an_unanswered_query_is_never_correct() -> None:
    # index -1 would be the last frame if read as an index; 0 is the query's own place
    truth = line_truth(3)
    o = match_outcomes(truth, result_of([-1, 1, 2], [-np.inf, 0.5, 0.4]))
    assert o.label.tolist() == [WRONG, CORRECT, CORRECT]
    assert np.isneginf(o.confidence[0])


# --------------------------------------------------------------------------- one cell


def test_evaluate_method_by_hand() -> None:
    # 6 frames 1 m apart, true place within 1 m: every query's own frame and its neighbours
    D = np.abs(np.subtract.outer(np.arange(6.0), np.arange(6.0)))
    D[2, 5] = -1.0  # query 2's nearest frame is 5, 3 m away: wrong; its true places rank 2..
    meth = MatrixMethod(D)
    ev = evaluate_method(meth, np.arange(6), np.arange(6), line_truth(6))
    assert ev.n_described == 12 and meth.calls == [6, 6]
    assert 0.0 <= ev.describe_s < 60 and 0.0 <= ev.matcher_s < 60
    assert list(ev.matches) == ["sequence", "single_frame"] == list(ev.metrics)
    assert list(ev.outcomes) == ["sequence", "single_frame"]
    sf = ev.matches["single_frame"]
    assert sf.index.tolist() == [0, 1, 5, 3, 4, 5]
    assert sf.config == EvaluationConfig().single_frame
    assert ev.matches["sequence"].config == MatcherConfig()
    o = ev.outcomes["single_frame"]
    assert o.true_rank is not None and o.true_rank.tolist() == [1, 1, 2, 1, 1, 1]
    assert ev.outcomes["sequence"].true_rank is None
    m = ev.metrics["single_frame"]
    assert m.n_correct == 5 and m.recall_at_1 == pytest.approx(5 / 6)
    assert m.recall_at_n == {1: pytest.approx(5 / 6), 5: 1.0, 10: 1.0}
    assert ev.metrics["sequence"].recall_at_n == {}


def test_max_frames_keeps_the_first_frames_on_both_sides() -> None:
    D = np.abs(np.subtract.outer(np.arange(8.0), np.arange(8.0)))
    meth = MatrixMethod(D)
    truth = line_truth(8)
    ev = evaluate_method(meth, np.arange(8), np.arange(8), truth,
                         config=EvaluationConfig(max_frames=5))
    assert meth.calls == [5, 5] and ev.n_described == 10
    assert len(ev.matches["sequence"].index) == 5
    m = ev.metrics["single_frame"]
    assert (m.n_queries, m.n_positive, m.recall_at_1) == (5, 5, 1.0)
    # more frames than the task has: all of them
    ev = evaluate_method(MatrixMethod(D), np.arange(8), np.arange(8), truth,
                         config=EvaluationConfig(max_frames=50))
    assert ev.metrics["single_frame"].n_queries == 8


def test_trim_queries_scores_the_middle_queries_with_their_own_ranks() -> None:
    n = 10
    D = np.abs(np.subtract.outer(np.arange(n, dtype=float), np.arange(n, dtype=float)))
    D[1, 9] = -1.0  # trimmed query 1 answers a wrong frame: must not count
    D[5, 8] = -1.0  # scored query 5 answers a wrong frame; its true places rank 2..
    truth = line_truth(n)
    ev = evaluate_method(MatrixMethod(D), np.arange(n), np.arange(n), truth,
                         config=EvaluationConfig(trim_queries=2))
    assert len(ev.matches["single_frame"].index) == n
    assert ev.matches["single_frame"].index[1] == 9
    o = ev.outcomes["single_frame"]
    assert len(o.label) == 6 and o.true_rank is not None
    assert o.true_rank.tolist() == [1, 1, 1, 2, 1, 1]
    want = true_place_ranks(D[2:8], [truth.true_matches(i) for i in range(2, 8)])
    assert o.true_rank.tolist() == want.tolist()
    assert o.label.tolist() == [CORRECT] * 3 + [WRONG] + [CORRECT] * 2
    m = ev.metrics["single_frame"]
    assert (m.n_queries, m.n_correct) == (6, 5)
    np.testing.assert_array_equal(ev.outcomes["sequence"].confidence,
                                  ev.matches["sequence"].confidence[2:8])


def test_revisit_evaluation_restricts_candidates_and_ranks() -> None:
    truth = revisit_truth()
    D = np.full((10, 10), 5.0)
    D[np.arange(10), np.arange(10)] = 0.0  # each query is nearest to itself: never a candidate
    D[5, 0] = 1.0  # query 5's true place
    D[9, 3], D[9, 4] = 1.0, 2.0  # query 9: a wrong candidate nearer than the true place 4
    ev = evaluate_method(MatrixMethod(D), np.arange(10), np.arange(10), truth, revisit=True)
    sf = ev.matches["single_frame"]
    assert sf.index.tolist()[:5] == [-1] * 5
    assert sf.index[5] == 0 and sf.index[9] == 3 and np.all(sf.index[5:] < 5)
    o = ev.outcomes["single_frame"]
    assert o.true_rank is not None and o.true_rank.tolist()[5:] == [1, 2, 0, 0, 2]  # 6: a tie with 0
    m = ev.metrics["single_frame"]
    assert (m.n_scored, m.n_positive) == (5, 3)
    # without revisit=True every frame is a candidate and the matcher answers each query itself
    free = evaluate_method(MatrixMethod(D), np.arange(10), np.arange(10), truth)
    assert free.matches["single_frame"].index.tolist() == list(range(10))


def test_a_method_whose_distance_has_the_wrong_shape() -> None:
    class Bad(MatrixMethod):
        def distance(self, q: np.ndarray, db: np.ndarray) -> np.ndarray:
            return np.zeros((len(db), len(q)))

    with pytest.raises(DataError, match=r"^method 'matrix': distance returned shape \(2, 3\), "
                                        r"expected \(3, 2\)$"):
        evaluation.difference_matrix(Bad(np.zeros((3, 2))), np.arange(3), np.arange(2))


def test_describing_cost_through_the_descriptor_cache(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[int] = []

    def fake(method: Any, views: Any) -> tuple[np.ndarray, float, int]:
        assert isinstance(method, Cached)
        calls.append(len(views))
        return np.asarray(views, dtype=np.float64)[:, None], 0.5, 0

    monkeypatch.setattr(descriptor_cache, "cached_describe", fake)

    class Cached(MatrixMethod):
        cache_descriptors = True

    meth = Cached(np.zeros((3, 2)))
    D, seconds, n = evaluation.difference_matrix(meth, np.arange(3), np.arange(2))
    assert calls == [2, 3] and meth.calls == []  # database first, then the queries
    assert seconds == pytest.approx(2.5) and n == 5 and D.shape == (3, 2)
    assert evaluation.describe(meth, np.arange(4))[1] == pytest.approx(2.0)

    class Points(Cached):
        input_kind = "points"  # the cache holds top-view descriptors only

    class Plain:
        name = "plain"
        input_kind = "topview"  # no cache_descriptors attribute: no cache

        def describe(self, views: np.ndarray) -> np.ndarray:
            return np.asarray(views, dtype=np.float64)[:, None]

    calls.clear()
    for meth2 in (Points(np.zeros((3, 2))), Plain()):
        desc, s = evaluation.describe(meth2, np.arange(4))  # type: ignore[arg-type]
        assert desc.shape == (4, 1) and 0.0 <= s < 60
    assert calls == []


# --------------------------------------------------------------------------- subsets


def test_scored_queries() -> None:
    assert scored_queries(10, 0) == slice(0, 10)
    assert scored_queries(10, 3) == slice(3, 7)
    assert scored_queries(3, 1) == slice(1, 2)
    for n, trim in ((10, 5), (2, 1), (3, 2)):
        with pytest.raises(ConfigError, match=rf"^trim_queries={trim} and 0 context queries leave none of the {n} "):
            scored_queries(n, trim)
    # the task's context queries and the trim leave the same leading queries out: no sum
    assert scored_queries(300, 5, context=10) == slice(10, 295)
    assert scored_queries(200, 20, context=10) == slice(20, 180)
    assert scored_queries(12, 0, context=10) == slice(10, 12)
    with pytest.raises(ConfigError, match="10 context queries leave none of the 10"):
        scored_queries(10, 0, context=10)


def test_subset_truth_keeps_the_protocol() -> None:
    truth = revisit_truth()
    part = subset_truth(truth, slice(5, 9), slice(0, 3))
    assert part.query_positions.tolist() == truth.query_positions[5:9].tolist()
    assert part.query_times.tolist() == truth.query_times[5:9].tolist()
    assert part.database_positions.tolist() == truth.database_positions[:3].tolist()
    assert part.database_times.tolist() == truth.database_times[:3].tolist()
    assert (part.tp_radius, part.fp_radius, part.window_s) == (3.0, 20.0, 30.0)
    assert [part.true_matches(i).tolist() for i in range(4)] == [[0], [1], [], []]


def test_subset_result_slices_every_field() -> None:
    D = np.random.default_rng(0).random((6, 8))
    res = match(D, MatcherConfig(ds=2), keep_S=True)
    assert subset_result(res, slice(0, 6)) is res
    part = subset_result(res, slice(1, 4))
    for name in ("index", "score", "best_s", "velocity", "n_terms", "complete"):
        np.testing.assert_array_equal(getattr(part, name), getattr(res, name)[1:4], err_msg=name)
    assert part.S is not None and res.S is not None
    np.testing.assert_array_equal(part.S, res.S[1:4])
    assert part.config == res.config
    no_s = subset_result(match(D, MatcherConfig(ds=2)), slice(2, 6))
    assert no_s.S is None and len(no_s.index) == 4


def test_ranks_follow_the_matchers_precision() -> None:
    # query 0's true place (frame 0) is 1e-9 farther than the wrong frame 2: a tie in float32
    # (the lower index, the true place, wins), not in float64 (frame 2 wins)
    D = np.array([[0.3 + 1e-9, 5.0, 0.3], [5.0, 0.0, 5.0], [5.0, 5.0, 0.0]])
    truth = GroundTruth(np.array([[0.0, 0], [50, 0], [100, 0]]),
                        np.array([[0.0, 0], [50, 0], [100, 0]]), np.zeros(3), np.zeros(3),
                        tp_radius=1.0, fp_radius=1.0)
    for dtype, index, rank in (("float32", 0, 1), ("float64", 2, 2)):
        cfg = EvaluationConfig(MatcherConfig(dtype=dtype))  # type: ignore[arg-type]
        ev = evaluate_method(MatrixMethod(D), np.arange(3), np.arange(3), truth, config=cfg)
        assert ev.matches["single_frame"].index[0] == index, dtype
        o = ev.outcomes["single_frame"]
        assert o.true_rank is not None and o.true_rank[0] == rank, dtype
        m = ev.metrics["single_frame"]
        assert m.recall_at_n[1] == m.recall_at_1, dtype
