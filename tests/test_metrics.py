"""Metrics against hand-computed values, the label helpers, and degenerate cases."""

from __future__ import annotations

import json

import numpy as np
import pytest

from safl_bench import metrics
from safl_bench.errors import DataError

T, F = True, False


def test_hand_computed_small_case() -> None:
    # thresholds 0.9, 0.8, 0.7, 0.6 -> (P, R) = (1, .25), (1, .5), (2/3, .5), (.75, .75)
    m = metrics.evaluate([0.9, 0.8, 0.7, 0.6], [T, T, F, T], [T, T, T, T])
    np.testing.assert_allclose(m.thresholds, [0.6, 0.7, 0.8, 0.9])
    np.testing.assert_allclose(m.precision, [0.75, 2 / 3, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(m.recall, [0.75, 0.5, 0.5, 0.25, 0.0])
    assert m.recall_at_100 == pytest.approx(0.5)
    assert m.recall_at_precision == pytest.approx(0.5)
    assert m.f1_max == pytest.approx(0.75)
    assert m.precision_at_min_recall == 1.0
    assert m.extended_precision == pytest.approx(0.75)
    assert m.roc_auc == pytest.approx(2 / 3)
    assert (m.n_queries, m.n_positive, m.n_correct, m.n_claimed) == (4, 4, 3, 4)


def test_recall_denominator_counts_missed_and_unclaimed_queries() -> None:
    # a 5th query claims nothing but has a true place; a 6th has none and is wrong
    conf = [0.9, 0.8, 0.7, 0.6, -np.inf, 0.1]
    m = metrics.evaluate(conf, [T, T, F, T, F, F], [T, T, T, T, T, F])
    assert m.n_positive == 5 and m.n_claimed == 5
    assert m.recall_at_100 == pytest.approx(2 / 5)
    assert m.recall.max() == pytest.approx(3 / 5)
    # ROC: positives .9 .8 .6; negatives .7, .1, (-inf ranked lowest): 8 of 9 pairs ordered
    assert m.roc_auc == pytest.approx(8 / 9)
    p99 = metrics.evaluate(conf, [T, T, F, T, F, F], [T, T, T, T, T, F], precision_level=0.7)
    assert p99.recall_at_precision == pytest.approx(3 / 5)
    assert p99.recall_at_100 == pytest.approx(2 / 5)


def test_valid_mask_leaves_queries_out() -> None:
    m = metrics.evaluate([0.9, 0.8, 0.7], [T, F, T], [T, T, T], valid=[T, F, T])
    assert m.n_valid == 2 and m.n_positive == 2
    assert m.recall_at_100 == 1.0 and m.roc_auc is None


def test_all_equal_confidences() -> None:
    m = metrics.evaluate([0.5] * 4, [T, F, T, F], [T] * 4)
    assert m.thresholds.tolist() == [0.5]
    assert m.recall_at_100 == 0.0
    assert m.f1_max == pytest.approx(0.5)
    assert m.roc_auc == pytest.approx(0.5)
    assert m.extended_precision == pytest.approx(0.25)


def test_no_correct_match_is_defined() -> None:
    m = metrics.evaluate([3.0, 2.0, 1.0], [F, F, F], [T, T, T])
    assert m.recall_at_100 == 0.0 and m.f1_max == 0.0 and m.extended_precision == 0.0
    assert m.roc_auc is None and m.notes
    assert np.all(m.recall == 0)


def test_all_correct() -> None:
    m = metrics.evaluate([3.0, 2.0, 1.0], [T, T, T], [T, T, T])
    assert m.recall_at_100 == 1.0 and m.extended_precision == 1.0 and m.roc_auc is None


def test_nothing_claimed() -> None:
    m = metrics.evaluate([-np.inf, -np.inf], [F, F], [T, T])
    assert m.n_claimed == 0 and m.recall_at_100 == 0.0 and m.f1_max == 0.0


@pytest.mark.parametrize(
    "args",
    [
        ([], [], []),
        ([np.nan, 1.0], [T, F], [T, T]),
        ([np.inf, 1.0], [T, F], [T, T]),
        ([1.0, 2.0], [T], [T, T]),
        ([1.0, 2.0], [T, F], [F, F]),  # correct without a true place
        ([1.0, 2.0], [F, F], [F, F]),  # no positives: recall undefined
        ([1.0, 2.0], [0.5, 1], [T, T]),
        ([[1.0, 2.0]], [T, F], [T, T]),
    ],
)
def test_degenerate_inputs_raise_data_error(args: tuple) -> None:
    with pytest.raises(DataError):
        metrics.evaluate(*args)


def test_to_dict_is_strict_json() -> None:
    m = metrics.evaluate([0.9, -np.inf, 0.3], [T, F, F], [T, T, T])
    blob = json.loads(json.dumps(m.to_dict(), allow_nan=False))
    assert blob["roc_auc"] == pytest.approx(1.0)
    assert blob["roc_thresholds"][0] is None  # sklearn's leading +inf threshold
    assert set(blob) >= {"precision", "recall", "f1_max", "extended_precision"}


def test_confidence_from_score_orientation() -> None:
    conf = metrics.confidence_from_score(np.array([0.1, 2.0, np.inf]))
    assert conf.tolist() == [-0.1, -2.0, -np.inf]


def test_paper_labels() -> None:
    db = np.c_[np.arange(10.0) * 5, np.zeros(10)]
    q = db + np.array([1.0, 0.0])
    index = np.array([0, 3, 0, 9, -1, 5, 6, 7, 8, 9])
    lab = metrics.paper_labels(q, db, index)
    np.testing.assert_allclose(lab.match_distance[:4], [1.0, 9.0, 11.0, 29.0])
    assert lab.is_correct.tolist()[:5] == [T, T, F, F, F]
    assert lab.has_true_place.all() and lab.valid.all()
    assert np.isinf(lab.match_distance[4])
    with pytest.raises(DataError):
        metrics.paper_labels(q, db, np.full(10, 10))
    with pytest.raises(DataError):
        metrics.paper_labels(q[:, :1], db, index)


def test_revisit_labels_band_and_eligibility() -> None:
    # a route that comes back: frames 0-4 at x = 0..40, frames 5-9 revisit x = 0..40 offset
    xy = np.r_[np.c_[np.arange(5) * 10.0, np.zeros(5)],
               np.c_[np.arange(5) * 10.0 + [1, 2, 5, 30, 0], np.zeros(5)]]
    limit = np.r_[np.zeros(5, int), np.full(5, 5)]  # only frames 0-4 eligible for 5-9
    index = np.array([-1, -1, -1, -1, -1, 0, 1, 0, 4, 4])
    lab = metrics.revisit_labels(xy, xy, index, db_limit=limit)
    # distances: 5->0: 1, 6->1: 2, 7->0: 25, 8->4: 0 (x 60 vs 40 -> 20), 9->4: 0
    np.testing.assert_allclose(lab.match_distance[5:], [1.0, 2.0, 25.0, 20.0, 0.0])
    assert lab.is_correct.tolist() == [F] * 5 + [T, T, F, F, T]
    assert lab.valid.tolist() == [T] * 5 + [T, T, T, F, T]  # 20 m is in the 3-20 band
    assert lab.has_true_place.tolist() == [F] * 5 + [T, T, F, F, T]
    m = metrics.evaluate_labels(-np.arange(10.0), lab)
    assert m.n_valid == 9 and m.n_positive == 3
