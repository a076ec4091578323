"""Every measure of `safl_bench.metrics` against values worked out by hand, its degenerate cases,
and the invariants a user relies on (property tests)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from safl_bench import metrics
from safl_bench.errors import DataError

T, F = True, False


def test_hand_computed_small_case() -> None:
    # confidences .9 .8 .7 .6 with correct, correct, wrong, correct; every query a positive.
    # thresholds .9 .8 .7 .6 -> (precision, recall) = (1, 1/4), (1, 2/4), (2/3, 2/4), (3/4, 3/4)
    m = metrics.evaluate([0.9, 0.8, 0.7, 0.6], [T, T, F, T], [T, T, T, T])
    np.testing.assert_allclose(m.thresholds, [0.6, 0.7, 0.8, 0.9])
    np.testing.assert_allclose(m.precision, [0.75, 2 / 3, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(m.recall, [0.75, 0.5, 0.5, 0.25, 0.0])
    np.testing.assert_allclose(m.recall_of_correct, [1.0, 2 / 3, 2 / 3, 1 / 3, 0.0])
    assert m.recall_at_100 == pytest.approx(0.5)
    assert m.recall_at_100_of_correct == pytest.approx(2 / 3)
    assert m.f1_max == pytest.approx(0.75)  # at .6: 2 * .75 * .75 / 1.5
    assert m.f1_max_of_correct == pytest.approx(2 * 0.75 / 1.75)  # at .6: P .75, Rc 1
    assert m.precision_at_min_recall == 1.0
    assert m.extended_precision == pytest.approx(0.75)
    assert m.extended_precision_of_correct == pytest.approx((1 + 2 / 3) / 2)
    assert m.roc_auc == pytest.approx(2 / 3)  # the wrong .7 outranks the correct .6 only
    assert m.recall_at_1 == pytest.approx(0.75)
    assert (m.n_queries, m.n_scored, m.n_positive, m.n_correct, m.n_claimed) == (4, 4, 4, 3, 4)


def test_the_two_recalls_differ_by_their_denominators() -> None:
    # a 5th query reports nothing but has a true place; a 6th has none and is wrong
    conf = [0.9, 0.8, 0.7, 0.6, -np.inf, 0.1]
    m = metrics.evaluate(conf, [T, T, F, T, F, F], [T, T, T, T, T, F])
    assert m.n_positive == 5 and m.n_correct == 3 and m.n_claimed == 5
    assert m.recall_at_100 == pytest.approx(2 / 5)
    assert m.recall_at_100_of_correct == pytest.approx(2 / 3)
    assert m.recall.max() == pytest.approx(3 / 5) == m.recall_at_1
    assert m.recall_of_correct.max() == pytest.approx(1.0)
    # ROC: correct .9 .8 .6; wrong .7, .1, and the unanswered one ranked lowest: 8 of 9 pairs
    assert m.roc_auc == pytest.approx(8 / 9)
    p70 = metrics.evaluate(conf, [T, T, F, T, F, F], [T, T, T, T, T, F], precision_level=0.7)
    assert p70.recall_at_precision == pytest.approx(3 / 5)
    assert p70.recall_at_precision_of_correct == pytest.approx(1.0)
    assert p70.recall_at_100 == pytest.approx(2 / 5)


def test_a_confident_false_positive_first_zeroes_recall_at_100() -> None:
    m = metrics.evaluate([0.99, 0.5, 0.4, 0.3], [F, T, T, T], [T, T, T, T])
    assert m.recall_at_100 == 0.0 and m.recall_at_100_of_correct == 0.0
    assert m.precision_at_min_recall == 0.0 and m.extended_precision == 0.0
    assert m.recall_at_1 == pytest.approx(0.75)
    assert m.f1_max == pytest.approx(2 * 0.75 * 0.75 / 1.5)
    assert m.roc_auc == 0.0  # the one wrong match outranks every correct one


def test_ambiguous_matches_are_neither_true_nor_false_positives_but_stay_positives() -> None:
    # query 2's match lies in the band: precision ignores it, the recall denominator keeps it
    m = metrics.evaluate([0.9, 0.8, 0.7], [T, F, T], [T, T, T], ambiguous=[F, T, F])
    assert m.n_positive == 3 and m.n_ambiguous == 1 and m.n_correct == 2
    assert m.recall_at_100 == pytest.approx(2 / 3)
    assert m.recall_at_100_of_correct == 1.0
    assert m.roc_auc is None  # what remains is correct only
    assert m.recall_at_1 == pytest.approx(2 / 3)


def test_equal_correct_matches_and_different_wrong_ones_give_the_same_recall() -> None:
    # two methods answer queries 0 and 1 correctly (most confident) and query 2 wrongly: one in
    # the ambiguous band, the other far away. The positives, hence the recalls, are the same.
    truth = [T, T, T, F]
    near = metrics.evaluate([0.9, 0.8, 0.7, 0.1], [T, T, F, F], truth, ambiguous=[F, F, T, F])
    far = metrics.evaluate([0.9, 0.8, 0.7, 0.1], [T, T, F, F], truth)
    assert near.n_positive == far.n_positive == 3
    for name in ("recall_at_100", "recall_at_100_of_correct", "recall_at_1"):
        assert getattr(near, name) == getattr(far, name), name
    assert near.recall_at_100 == pytest.approx(2 / 3)


def test_queries_without_a_candidate_are_left_out_of_every_measure() -> None:
    # eight answered queries with AUC 0.5, and four that could match nothing
    conf = [0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1] + [-np.inf] * 4
    correct = [T, F, F, T, T, F, F, T] + [F] * 4
    has_true = [T] * 8 + [F] * 4
    cand = [T] * 8 + [F] * 4
    m = metrics.evaluate(conf, correct, has_true, has_candidate=cand)
    assert m.n_queries == 12 and m.n_scored == 8
    assert m.roc_auc == pytest.approx(0.5)
    alone = metrics.evaluate(conf[:8], correct[:8], has_true[:8])
    assert alone.roc_auc == m.roc_auc and alone.f1_max == m.f1_max


def test_ties_in_confidence_are_one_threshold() -> None:
    m = metrics.evaluate([0.5] * 4, [T, F, T, F], [T] * 4)
    assert m.thresholds.tolist() == [0.5]
    assert m.recall_at_100 == 0.0
    assert m.f1_max == pytest.approx(0.5)
    assert m.roc_auc == pytest.approx(0.5)
    assert m.extended_precision == pytest.approx(0.25)
    assert m.extended_precision_of_correct == pytest.approx(0.25)


def test_no_correct_match_is_defined() -> None:
    m = metrics.evaluate([3.0, 2.0, 1.0], [F, F, F], [T, T, T])
    assert m.recall_at_100 == 0.0 and m.f1_max == 0.0 and m.extended_precision == 0.0
    assert m.recall_at_100_of_correct == 0.0 and m.f1_max_of_correct == 0.0
    assert m.roc_auc is None and m.notes
    assert np.all(m.recall == 0) and m.recall_at_1 == 0.0


def test_all_correct() -> None:
    m = metrics.evaluate([3.0, 2.0, 1.0], [T, T, T], [T, T, T])
    assert m.recall_at_100 == 1.0 and m.extended_precision == 1.0 and m.roc_auc is None
    assert m.f1_max == 1.0 and m.f1_max_of_correct == 1.0


def test_nothing_claimed() -> None:
    m = metrics.evaluate([-np.inf, -np.inf], [F, F], [T, T])
    assert m.n_claimed == 0 and m.recall_at_100 == 0.0 and m.f1_max == 0.0
    assert m.recall_at_1 == 0.0


@pytest.mark.parametrize(
    ("args", "kwargs"),
    [
        (([], [], []), {}),
        (([np.nan, 1.0], [T, F], [T, T]), {}),
        (([np.inf, 1.0], [T, F], [T, T]), {}),
        (([1.0, 2.0], [T], [T, T]), {}),
        (([1.0, 2.0], [T, F], [F, F]), {}),  # correct without a true place
        (([1.0, 2.0], [F, F], [F, F]), {}),  # no positives: recall undefined
        (([1.0, 2.0], [0.5, 1], [T, T]), {}),
        (([[1.0, 2.0]], [T, F], [T, T]), {}),
        (([1.0, 2.0], [T, F], [T, T]), {"ambiguous": [T, F]}),  # correct and ambiguous
        (([1.0, 2.0], [F, F], [T, T]), {"has_candidate": [F, T]}),  # true place, no candidate
    ],
)
def test_degenerate_inputs_raise_data_error(args: tuple, kwargs: dict) -> None:
    with pytest.raises(DataError):
        metrics.evaluate(*args, **kwargs)


def test_no_positive_is_its_own_error() -> None:
    with pytest.raises(metrics.NoPositivesError, match="no query has a true place among 2"):
        metrics.evaluate([1.0, 2.0], [F, F], [F, F])


def test_to_dict_is_strict_json() -> None:
    m = metrics.evaluate([0.9, -np.inf, 0.3], [T, F, F], [T, T, T])
    blob = json.loads(json.dumps(m.to_dict(), allow_nan=False))
    assert blob["roc_auc"] == pytest.approx(1.0)
    assert blob["roc_thresholds"][0] is None  # sklearn's leading +inf threshold
    assert set(blob) >= {"precision", "recall", "f1_max", "extended_precision",
                         "recall_at_100_of_correct"}


def test_confidence_from_score_orientation() -> None:
    conf = metrics.confidence_from_score(np.array([0.1, 2.0, np.inf]))
    assert conf.tolist() == [-0.1, -2.0, -np.inf]


# --------------------------------------------------------------------------- Recall@N


def test_true_place_ranks_and_recall_at_n_by_hand() -> None:
    D = np.array([[0.1, 0.5, 0.9], [0.9, 0.2, 0.1], [0.3, 0.2, 0.1]])
    true = [np.array([0]), np.array([0]), np.array([], dtype=np.int64)]
    ranks = metrics.true_place_ranks(D, true)
    assert ranks.tolist() == [1, 3, 0]
    assert metrics.recall_at_n(ranks, ranks > 0, (1, 2, 3)) == {1: 0.5, 2: 0.5, 3: 1.0}
    # query 1 may only match frame 0: its true place is then the nearest candidate
    limited = metrics.true_place_ranks(D, true, db_limit=np.array([3, 1, 3]))
    assert limited.tolist() == [1, 1, 0]


def test_true_place_ranks_break_ties_at_the_lower_index_in_the_matchers_precision() -> None:
    D = np.array([[0.5, 0.5, 0.5, 0.2]])
    assert metrics.true_place_ranks(D, [np.array([0])]).tolist() == [2]  # only frame 3 is nearer
    assert metrics.true_place_ranks(D, [np.array([2])]).tolist() == [4]  # 3, 0 and 1 come first
    # 1e-9 apart in float64, equal in float32: the float32 rule makes them a tie
    near = np.array([[0.3 + 1e-9, 0.3]])
    assert metrics.true_place_ranks(near, [np.array([0])]).tolist() == [1]
    assert metrics.true_place_ranks(near, [np.array([0])], dtype="float64").tolist() == [2]


def test_a_true_place_that_is_not_a_candidate_is_an_error() -> None:
    with pytest.raises(DataError, match="not a candidate"):
        metrics.true_place_ranks(np.zeros((1, 3)), [np.array([2])], db_limit=np.array([2]))


def test_recall_at_n_comes_with_ranks_in_evaluate_outcomes() -> None:
    o = metrics.outcomes([0.9, 0.8, 0.7], [T, F, F], [T, T, F], true_rank=[1, 4, 0])
    m = metrics.evaluate_outcomes(o, recall_at=(1, 5))
    assert m.recall_at_n == {1: 0.5, 5: 1.0} and m.recall_at_1 == 0.5
    with pytest.raises(DataError, match="true_rank"):
        metrics.outcomes([0.9], [T], [T], true_rank=[0])


# --------------------------------------------------------------------------- properties


@st.composite
def runs(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A random evaluation: confidences (with ties and unanswered queries), labels, positives."""
    n = draw(st.integers(2, 30))
    levels = draw(st.lists(st.sampled_from([0.1, 0.2, 0.5, 0.7, 0.9, -np.inf]), min_size=n,
                           max_size=n))
    has_true = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    has_true[0] = True
    label = np.array(draw(st.lists(st.sampled_from([-1, 0, 1]), min_size=n, max_size=n)))
    label = np.where(has_true, label, np.minimum(label, 0))
    return np.array(levels), label == 1, label == 0, has_true


def _measures(m: metrics.Metrics) -> dict[str, object]:
    names = ("recall_at_100", "recall_at_100_of_correct", "f1_max", "f1_max_of_correct",
             "extended_precision", "extended_precision_of_correct", "roc_auc", "recall_at_1",
             "n_positive", "n_correct")
    return {k: getattr(m, k) for k in names}


@settings(max_examples=150, deadline=None)
@given(runs(), st.randoms(use_true_random=False))
def test_permuting_queries_changes_nothing(run: tuple, rnd: object) -> None:
    conf, correct, band, has_true = run
    order = np.arange(len(conf))
    rnd.shuffle(order)  # type: ignore[attr-defined]
    a = metrics.evaluate(conf, correct, has_true, ambiguous=band)
    b = metrics.evaluate(conf[order], correct[order], has_true[order], ambiguous=band[order])
    for key, value in _measures(a).items():
        assert _measures(b)[key] == pytest.approx(value), key


@settings(max_examples=150, deadline=None)
@given(runs(), st.floats(0.05, 1.0))
def test_recall_at_100_never_exceeds_recall_at_a_lower_precision(run: tuple, level: float) -> None:
    conf, correct, band, has_true = run
    m = metrics.evaluate(conf, correct, has_true, ambiguous=band, precision_level=level)
    assert m.recall_at_100 <= m.recall_at_precision + 1e-12
    assert m.recall_at_100_of_correct <= m.recall_at_precision_of_correct + 1e-12
    assert m.recall_at_100 <= m.recall_at_1 + 1e-12  # nothing recalls more than accepting all
    assert m.recall_at_100 <= m.recall_at_100_of_correct + 1e-12  # C <= P
    assert 0.0 <= m.f1_max <= 1.0 and 0.0 <= m.extended_precision <= 1.0


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-5, 5), min_size=1, max_size=25))
def test_every_query_answered_correctly_scores_one_everywhere(conf: list[float]) -> None:
    n = len(conf)
    m = metrics.evaluate(conf, [T] * n, [T] * n)
    for name in ("recall_at_100", "recall_at_100_of_correct", "f1_max", "f1_max_of_correct",
                 "extended_precision", "extended_precision_of_correct", "recall_at_1"):
        assert getattr(m, name) == 1.0, name


@settings(max_examples=100, deadline=None)
@given(runs())
def test_the_positives_do_not_depend_on_the_answers(run: tuple) -> None:
    conf, correct, band, has_true = run
    m = metrics.evaluate(conf, correct, has_true, ambiguous=band)
    assert m.n_positive == int(has_true.sum())
    wrong_everywhere = metrics.evaluate(conf, np.zeros_like(correct), has_true)
    assert wrong_everywhere.n_positive == m.n_positive


def test_authors_recall_is_their_reading_of_the_pr_curve() -> None:
    """``authors_recall_at_99p``: plotPaper2.py lines 59-60 at commit 25be0fd, literally:
    ``precision_recall_curve(is_correct, score)``, then the recall at the first index whose
    precision is >= 0.99, over the correct matches."""
    from sklearn.metrics import precision_recall_curve

    rng = np.random.default_rng(11)
    for _ in range(50):
        n = int(rng.integers(5, 400))
        correct = rng.random(n) < rng.uniform(0.3, 1.0)
        conf = np.where(correct, rng.normal(1.0, 1.0, n), rng.normal(0.0, 1.0, n)).round(1)
        if not correct.any():
            continue
        m = metrics.evaluate(conf, correct, np.ones(n, bool))
        precision, recall, _ = precision_recall_curve(correct, conf)
        recall_id = next(x for x in range(len(precision)) if precision[x] >= 0.99)
        assert m.authors_recall_at_99p == pytest.approx(recall[recall_id], abs=1e-12)
    # by hand: 100 queries, one wrong match among the 100 most confident: precision .99 there,
    # so every correct match counts (1.0), where recall at 100 % precision stops before it
    conf = np.arange(100, 0, -1, dtype=float)
    correct = np.ones(100, bool)
    correct[10] = False
    m = metrics.evaluate(conf, correct, np.ones(100, bool))
    assert m.authors_recall_at_99p == 1.0 and m.recall_at_100 == pytest.approx(0.10)
    assert metrics.evaluate([0.5, 0.4], [F, F], [T, T]).authors_recall_at_99p == 0.0
