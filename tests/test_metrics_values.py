"""Exact values of every field of `safl_bench.metrics` on small hand-made cases: a case with
every kind of query at once, the degenerate cases and their notes, the input checks, Recall@N.
Each value below is worked out by hand from the module docstring's definitions."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from safl_bench import metrics
from safl_bench.errors import ConfigError, DataError

T, F = True, False
NINF = -np.inf


def rich_outcomes() -> metrics.Outcomes:
    """Six scored queries and two without a candidate:

    q0 .9 correct | q1 .8 ambiguous (has a true place) | q2 .7 wrong, no true place
    q3 .6 correct | q4 reported nothing (has a true place) | q5 .5 wrong (has a true place)
    q6, q7: no candidate (q7 even carries a confident wrong answer: it must not count)."""
    return metrics.outcomes(
        [0.9, 0.8, 0.7, 0.6, NINF, 0.5, NINF, 0.95],
        [T, F, F, T, F, F, F, F],
        [T, T, F, T, T, T, F, F],
        ambiguous=[F, T, F, F, F, F, F, F],
        has_candidate=[T, T, T, T, T, T, F, F],
        true_rank=[1, 3, 0, 1, 7, 2, 0, 0],
    )


def test_every_field_of_a_case_with_every_kind_of_query() -> None:
    o = rich_outcomes()
    assert o.label.tolist() == [1, 0, -1, 1, -1, -1, -1, -1]
    assert o.label.dtype == np.int8 and o.true_rank is not None and o.true_rank.dtype == np.int64
    m = metrics.evaluate_outcomes(o, precision_level=0.6, recall_at=(1, 2, 5))
    # P = q0 q1 q3 q4 q5; C = q0 q3; decided (TP or FP): q0 q2 q3 q5 at .9 .7 .6 .5
    assert (m.n_queries, m.n_scored, m.n_positive, m.n_correct, m.n_ambiguous, m.n_claimed) == (
        8, 6, 5, 2, 1, 5)
    np.testing.assert_allclose(m.thresholds, [0.5, 0.6, 0.7, 0.9])
    np.testing.assert_allclose(m.precision, [0.5, 2 / 3, 0.5, 1.0, 1.0])
    np.testing.assert_allclose(m.recall_of_correct, [1.0, 1.0, 0.5, 0.5, 0.0])
    np.testing.assert_allclose(m.recall, [0.4, 0.4, 0.2, 0.2, 0.0])
    assert m.recall_at_100 == pytest.approx(0.2)
    assert m.recall_at_100_of_correct == pytest.approx(0.5)
    assert m.precision_level == 0.6
    assert m.recall_at_precision == pytest.approx(0.4)  # at .6: precision 2/3
    assert m.recall_at_precision_of_correct == pytest.approx(1.0)
    assert m.precision_at_min_recall == 1.0
    assert m.extended_precision == pytest.approx(0.6)
    assert m.extended_precision_of_correct == pytest.approx(0.75)
    assert m.f1_max == pytest.approx(0.5)  # at .6: 2 (2/3)(.4) / (2/3 + .4)
    assert m.f1_max_of_correct == pytest.approx(0.8)  # at .6: 2 (2/3)(1) / (5/3)
    assert m.recall_at_1 == pytest.approx(0.4)
    assert m.recall_at_n == {1: 0.4, 2: 0.6, 5: 0.8}
    # ROC over q0 q2 q3 q4 q5 (the ambiguous q1 left out): correct .9 .6; wrong .7 .5 and q4,
    # which reported nothing and ranks one below the least confident match (.5 - 1)
    assert m.roc_auc == pytest.approx(5 / 6)
    np.testing.assert_allclose(m.roc_thresholds, [np.inf, 0.9, 0.7, 0.6, -0.5])
    np.testing.assert_allclose(m.fpr, [0, 0, 1 / 3, 1 / 3, 1])
    np.testing.assert_allclose(m.tpr, [0, 0.5, 0.5, 1, 1])
    assert m.notes == []


def test_to_dict_holds_every_field_as_strict_json() -> None:
    m = metrics.evaluate_outcomes(rich_outcomes(), recall_at=(1,))
    blob = json.loads(json.dumps(m.to_dict(), allow_nan=False))
    assert set(blob) == {f for f in m.__dataclass_fields__}
    assert blob["roc_thresholds"] == [None, 0.9, 0.7, 0.6, -0.5]  # +inf -> None, floats kept
    assert blob["precision"] == pytest.approx([0.5, 2 / 3, 0.5, 1.0, 1.0])
    assert blob["n_positive"] == 5 and blob["recall_at_n"] == {"1": 0.4}
    assert blob["notes"] == [] and blob["roc_auc"] == pytest.approx(5 / 6)


def test_recall_at_n_needs_ranks_and_ns() -> None:
    o = rich_outcomes()
    assert metrics.evaluate_outcomes(o).recall_at_n == {}  # no N asked
    no_ranks = metrics.outcomes(o.confidence, o.label == 1, o.has_true_place,
                                ambiguous=o.label == 0, has_candidate=o.has_candidate)
    assert no_ranks.true_rank is None
    assert metrics.evaluate_outcomes(no_ranks, recall_at=(1, 5)).recall_at_n == {}


def test_precision_level_bounds() -> None:
    o = rich_outcomes()
    for bad in (0.0, -0.5, 1.0001):
        with pytest.raises(ConfigError, match="precision_level"):
            metrics.evaluate_outcomes(o, precision_level=bad)
    one = metrics.evaluate_outcomes(o, precision_level=1.0)
    assert one.recall_at_precision == one.recall_at_100 == pytest.approx(0.2)
    # just below 1 is not "exactly 1": precision 1 still qualifies, nothing lower does
    near = metrics.evaluate_outcomes(o, precision_level=0.999)
    assert near.recall_at_precision == pytest.approx(0.2)
    half = metrics.evaluate_outcomes(o, precision_level=0.5)  # every threshold qualifies
    assert half.recall_at_precision == pytest.approx(0.4)
    # a precision exactly at the level qualifies: 2/3 at threshold .6 (recall .4)
    two_thirds = metrics.evaluate_outcomes(o, precision_level=2 / 3)
    assert two_thirds.recall_at_precision == pytest.approx(0.4)
    assert two_thirds.recall_at_precision_of_correct == 1.0


def test_no_correct_match_gives_zeros_and_says_so() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # F1 of precision 0 and recall 0 is 0, not 0 / 0
        m = metrics.evaluate([0.9, 0.7, 0.7, NINF], [F, F, F, F], [T, T, F, T],
                             ambiguous=[F, T, F, F])
    assert m.notes == ["no correct match: every recall, F1 and extended precision is 0",
                       "ROC AUC undefined: every match it reads is wrong"]
    # decided: .9 and .7 (the other .7 is ambiguous): two thresholds, precision 0 at both
    np.testing.assert_array_equal(m.thresholds, [0.7, 0.9])
    np.testing.assert_array_equal(m.precision, [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(m.recall, [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(m.recall_of_correct, [0.0, 0.0, 0.0])
    assert m.precision_at_min_recall == 0.0
    assert (m.recall_at_100, m.f1_max, m.f1_max_of_correct, m.extended_precision,
            m.extended_precision_of_correct, m.recall_at_1) == (0.0,) * 6
    assert m.roc_auc is None and m.fpr.size == m.tpr.size == m.roc_thresholds.size == 0
    assert (m.n_positive, m.n_correct, m.n_ambiguous, m.n_claimed) == (3, 0, 1, 3)


def test_only_ambiguous_or_no_answers_have_no_pr_curve() -> None:
    m = metrics.evaluate([0.9, NINF], [F, F], [T, T], ambiguous=[T, F])
    assert m.notes == ["no correct match: every recall, F1 and extended precision is 0",
                       "no query reported a match outside the ambiguous band",
                       "ROC AUC undefined: every match it reads is wrong"]
    assert m.thresholds.size == 0 and m.precision.tolist() == [1.0]
    assert m.recall.tolist() == [0.0] and m.precision_at_min_recall == 0.0
    assert m.extended_precision == 0.0 and m.f1_max == 0.0
    nothing = metrics.evaluate([NINF, NINF], [F, F], [T, F])
    assert nothing.n_claimed == 0 and nothing.roc_auc is None
    assert "no query reported a match outside the ambiguous band" in nothing.notes


def test_every_match_correct_has_no_roc_and_says_so() -> None:
    m = metrics.evaluate([0.4, 0.9], [T, T], [T, T])
    assert m.notes == ["ROC AUC undefined: every match it reads is correct"]
    assert m.roc_auc is None and m.fpr.size == 0
    assert m.precision_at_min_recall == 1.0 and m.recall_at_100 == 1.0


def test_unanswered_queries_rank_below_every_answer_in_the_roc() -> None:
    # correct -3, wrong -5 and two wrong queries that reported nothing: ranked at -6, not -inf
    m = metrics.evaluate([-3.0, -5.0, NINF, NINF], [T, F, F, F], [T, T, T, T])
    assert m.roc_auc == 1.0
    np.testing.assert_allclose(m.roc_thresholds, [np.inf, -3.0, -5.0, -6.0])
    # a correct match below an unanswered query would be impossible: unanswered are lowest
    low = metrics.evaluate([-3.0, -5.0, NINF], [F, T, F], [T, T, T])
    assert low.roc_auc == pytest.approx(0.5)  # wrong -3 > correct -5 > unanswered -6


def test_one_confident_correct_match_then_wrong_ones() -> None:
    m = metrics.evaluate([0.9, 0.8, 0.7], [T, F, F], [T, T, T])
    assert m.recall_at_100 == pytest.approx(1 / 3) and m.recall_at_100_of_correct == 1.0
    assert m.precision_at_min_recall == 1.0
    assert m.extended_precision == pytest.approx(2 / 3)
    assert m.f1_max == pytest.approx(0.5)  # at .9: P 1, R 1/3
    assert m.f1_max_of_correct == 1.0
    assert m.roc_auc == 1.0


# --------------------------------------------------------------------------- input checks


def test_integer_zero_one_arrays_are_booleans() -> None:
    o = metrics.outcomes([0.5, 0.4], np.array([1, 0]), np.array([1, 1], dtype=np.int64),
                         ambiguous=np.array([0, 1]), has_candidate=np.array([1, 1]))
    assert o.has_true_place.dtype == bool and o.has_candidate.dtype == bool
    assert o.label.tolist() == [metrics.CORRECT, metrics.AMBIGUOUS]
    assert o.has_candidate.tolist() == [T, T]


@pytest.mark.parametrize("bad", [np.array([2, 0]), np.array([0.0, 1.0]), np.array([-1, 0])])
def test_other_arrays_are_not_booleans(bad: np.ndarray) -> None:
    with pytest.raises(DataError, match="is_correct must be boolean"):
        metrics.outcomes([0.5, 0.4], bad, [T, T])


def test_shapes_must_match_the_confidences() -> None:
    with pytest.raises(DataError, match=r"has_true_place must have shape \(2,\)"):
        metrics.outcomes([0.5, 0.4], [T, F], [T])
    with pytest.raises(DataError, match="ambiguous must have shape"):
        metrics.outcomes([0.5, 0.4], [T, F], [T, T], ambiguous=[F])
    with pytest.raises(DataError, match="has_candidate must have shape"):
        metrics.outcomes([0.5, 0.4], [T, F], [T, T], has_candidate=[[T, T]])


def test_confidence_checks() -> None:
    with pytest.raises(DataError, match=r"^nothing to evaluate: no queries$"):
        metrics.outcomes(0.5, [T], [T])  # a scalar is no queries
    with pytest.raises(DataError, match=r"^nothing to evaluate: no queries$"):
        metrics.outcomes([], [], [])
    with pytest.raises(DataError, match=r"^confidence must be 1-D"):
        metrics.outcomes([[0.5]], [T], [T])
    with pytest.raises(DataError, match=r"^confidence has 2 NaN values$"):
        metrics.outcomes([np.nan, 0.1, np.nan], [F, F, F], [T, T, T])
    with pytest.raises(DataError, match=r"^confidence has \+inf values \(a score of -inf\?\)$"):
        metrics.outcomes([np.inf, 0.1], [F, F], [T, T])
    o = metrics.outcomes([NINF, 0.1], [F, F], [T, T])  # -inf is "no match", allowed
    assert o.confidence.dtype == np.float64 and o.confidence[0] == NINF
    assert metrics.outcomes([3, 2], [F, F], [T, T]).confidence.dtype == np.float64


def test_inconsistent_labels_are_errors_naming_the_problem() -> None:
    with pytest.raises(DataError, match=r"^a reported match is marked both correct and ambiguous$"):
        metrics.outcomes([0.5], [T], [T], ambiguous=[T])
    with pytest.raises(DataError, match=r"^a query is marked correct but has no true place$"):
        metrics.outcomes([0.5], [T], [F])
    with pytest.raises(DataError, match=r"^a query has a true place but no candidate$"):
        metrics.outcomes([0.5], [F], [T], has_candidate=[F])
    # a query without a candidate and without a true place is fine
    o = metrics.outcomes([0.5, 0.4], [F, T], [F, T], has_candidate=[F, T])
    assert o.has_candidate.tolist() == [F, T]


@pytest.mark.parametrize("rank", [[1, -1], [1.0, 0.0], [[1, 0]], [1]])
def test_true_rank_must_be_integers_of_the_right_shape(rank: list) -> None:
    with pytest.raises(DataError, match=r"^true_rank must be integers >= 0"):
        metrics.outcomes([0.5, 0.4], [T, F], [T, F], true_rank=rank)


def test_true_rank_must_be_positive_exactly_where_a_true_place_is() -> None:
    with pytest.raises(DataError, match=r"^true_rank must be >= 1 exactly where"):
        metrics.outcomes([0.5, 0.4], [T, F], [T, F], true_rank=[1, 2])
    with pytest.raises(DataError, match=r"^true_rank must be >= 1 exactly where"):
        metrics.outcomes([0.5, 0.4], [T, F], [T, F], true_rank=[0, 0])
    o = metrics.outcomes([0.5, 0.4], [T, F], [T, F], true_rank=np.array([3, 0], np.int32))
    assert o.true_rank is not None and o.true_rank.dtype == np.int64


def test_no_positive_among_the_scored_queries_is_an_error() -> None:
    # the only query with a true place has a candidate; the scored one has none
    with pytest.raises(metrics.NoPositivesError,
                       match=r"^no query has a true place among 3 queries "
                             r"\(2 with a candidate\): recall is undefined$"):
        metrics.evaluate([0.5, 0.4, NINF], [F, F, F], [F, F, F], has_candidate=[T, T, F])


def test_confidence_from_score_is_a_float64_negation() -> None:
    conf = metrics.confidence_from_score(np.array([1, 3], dtype=np.int64))
    assert conf.dtype == np.float64 and conf.tolist() == [-1.0, -3.0]


# --------------------------------------------------------------------------- ranks


def test_true_place_ranks_of_several_true_places_count_the_nearest() -> None:
    D = np.array([[0.4, 0.1, 0.3, 0.2, 0.0]])
    # true places 0 and 2: the nearer is 2 (0.3); frames 4, 1, 3 are nearer still
    assert metrics.true_place_ranks(D, [np.array([0, 2])]).tolist() == [4]
    # with frames j < 3 only: 1 is the one nearer candidate
    assert metrics.true_place_ranks(D, [np.array([0, 2])], db_limit=np.array([3])).tolist() == [2]
    assert metrics.true_place_ranks(D, [[4]]).tolist() == [1]
    # indices and limits read back as floats (JSON) are still indices
    assert metrics.true_place_ranks(D, [np.array([0.0, 2.0])],
                                    db_limit=np.array([3.0])).tolist() == [2]
    # a tie between two true places: the lower index is the one ranked
    tie = np.array([[0.2, 0.1, 0.2, 0.2]])
    assert metrics.true_place_ranks(tie, [np.array([2, 3])]).tolist() == [3]  # 1 and 0 first


def test_true_place_ranks_checks() -> None:
    with pytest.raises(ConfigError, match="dtype must be 'float32' or 'float64'"):
        metrics.true_place_ranks(np.zeros((1, 2)), [[0]], dtype="float16")
    with pytest.raises(DataError, match=r"need an \(Nq, Ndb\) matrix"):
        metrics.true_place_ranks(np.zeros(3), [[0]])
    with pytest.raises(DataError, match=r"need an \(Nq, Ndb\) matrix"):
        metrics.true_place_ranks(np.zeros((2, 3)), [[0]])
    with pytest.raises(DataError, match=r"^query 0: a true place 3 is not a candidate "
                                        r"\(candidates: j < 3\)$"):
        metrics.true_place_ranks(np.zeros((1, 4)), [[3]], db_limit=[3])
    with pytest.raises(DataError, match="not a candidate"):
        metrics.true_place_ranks(np.zeros((1, 4)), [[-1]])
    with pytest.raises(DataError, match="not a candidate"):
        metrics.true_place_ranks(np.zeros((1, 4)), [[4]])
    # the last frame is a candidate without a limit
    assert metrics.true_place_ranks(np.zeros((1, 4)), [[3]]).tolist() == [4]


def test_true_place_ranks_of_more_queries_than_a_row_block() -> None:
    # the ranks are counted 256 queries with a true place at a time: 800 queries (the first 50
    # without a true place, all with a limit or none) must get the ranks of a plain count
    n = 800
    rng = np.random.default_rng(4)
    D = rng.integers(0, 30, (n, 40)).astype(np.float32)  # ties included
    true = [np.sort(rng.choice(30, 0 if i < 50 else rng.integers(1, 3), replace=False))
            for i in range(n)]
    limit = rng.integers(30, 41, n)
    for db_limit in (None, limit):
        got = metrics.true_place_ranks(D, true, db_limit=db_limit)
        for i in range(n):
            js = np.asarray(true[i], dtype=np.int64)
            if not js.size:
                assert got[i] == 0
                continue
            j = js[np.argmin(D[i, js])]
            cand = np.arange(40 if db_limit is None else limit[i])
            nearer = (D[i, cand] < D[i, j]) | ((D[i, cand] == D[i, j]) & (cand < j))
            assert got[i] == 1 + int(nearer.sum()), i


def test_recall_at_n_by_hand() -> None:
    ranks = np.array([1, 0, 3, 2, 10])
    has = ranks > 0
    assert metrics.recall_at_n(ranks, has, (1, 2, 3, 9, 10)) == {
        1: 0.25, 2: 0.5, 3: 0.75, 9: 0.75, 10: 1.0}
    assert metrics.recall_at_n(ranks, np.zeros(5, bool), (1,)) == {}
    # 0/1 flags are flags, not indices
    assert metrics.recall_at_n(ranks, has.astype(int), (1, 10)) == {1: 0.25, 10: 1.0}
    out = metrics.recall_at_n(ranks, has, (np.int64(5),))
    assert list(out) == [5] and type(next(iter(out))) is int
