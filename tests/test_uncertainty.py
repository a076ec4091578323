"""Intervals over seeds and queries, and paired differences (`safl_bench.uncertainty`)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from record_factory import random_outcomes, scored_record

from safl_bench import metrics, uncertainty
from safl_bench.errors import DataError

NAMES = {"recall_at_100_precision": "recall_at_100",
         "recall_at_100_precision_of_correct": "recall_at_100_of_correct",
         "f1_max": "f1_max", "f1_max_of_correct": "f1_max_of_correct",
         "extended_precision": "extended_precision",
         "extended_precision_of_correct": "extended_precision_of_correct",
         "auc": "roc_auc", "recall_at_1": "recall_at_1",
         "authors_recall_at_99p": "authors_recall_at_99p"}


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), st.integers(3, 60), st.floats(0.0, 1.0))
def test_the_weighted_measures_at_unit_weights_are_the_metrics(seed: int, n: int, skill: float) -> None:
    o = random_outcomes(seed, n, skill)
    try:
        m = metrics.evaluate_outcomes(o, recall_at=(5, 10))
    except metrics.NoPositivesError:
        return
    got = uncertainty.weighted_measures(o, np.ones((1, n)))
    for ours, theirs in NAMES.items():
        expected = getattr(m, theirs)
        if expected is None:
            assert np.isnan(got[ours][0]), ours
        else:
            assert got[ours][0] == pytest.approx(expected, abs=1e-12), ours
    assert got["recall_at_5"][0] == pytest.approx(m.recall_at_n[5])


def test_weights_count_queries_like_repeating_them() -> None:
    o = random_outcomes(3, 40)
    w = np.random.default_rng(0).integers(0, 3, (1, 40))
    w[0, 0] = 1  # keep a positive
    keep = np.repeat(np.arange(40), w[0])
    repeated = metrics.Outcomes(o.confidence[keep], o.label[keep], o.has_true_place[keep],
                                o.has_candidate[keep], o.true_rank[keep])
    m = metrics.evaluate_outcomes(repeated)
    got = uncertainty.weighted_measures(o, w)
    for ours, theirs in NAMES.items():
        expected = getattr(m, theirs)
        assert got[ours][0] == pytest.approx(np.nan if expected is None else expected,
                                             nan_ok=True), ours


def test_block_weights_draw_n_queries_in_runs() -> None:
    w = uncertainty.block_weights(25, 50, np.random.default_rng(1), block=10)
    assert w.shape == (50, 25) and (w.sum(axis=1) == 25).all()
    assert uncertainty.block_weights(3, 2, np.random.default_rng(1), block=10).sum() == 6


def test_an_interval_holds_its_mean_and_narrows_with_more_seeds() -> None:
    one = uncertainty.bootstrap([random_outcomes(0)], replicates=300)
    five = uncertainty.bootstrap([random_outcomes(s) for s in range(5)], replicates=300)
    for name in ("f1_max", "recall_at_1", "auc"):
        for cell in (one, five):
            assert cell[name].low <= cell[name].mean <= cell[name].high, name
        assert five[name].high - five[name].low < one[name].high - one[name].low, name
    assert five["f1_max"].n_seeds == 5 and one["f1_max"].n_queries == 200
    again = uncertainty.bootstrap([random_outcomes(0)], replicates=300)
    assert again == one  # deterministic


def test_paired_differences_resolve_a_better_method_and_tie_a_method_with_itself() -> None:
    good = [random_outcomes(s, skill=0.9) for s in range(3)]
    # the same queries answered worse: same positives, fewer correct matches
    bad = []
    for o in good:
        worse = o.label.copy()
        worse[::2] = np.where(o.label[::2] == metrics.CORRECT, metrics.WRONG, o.label[::2])
        bad.append(metrics.Outcomes(o.confidence, worse, o.has_true_place, o.has_candidate,
                                    np.where(o.has_true_place, np.where(worse == 1, 1, 5), 0)))
    diff = uncertainty.paired_difference(good, bad, replicates=300)
    assert diff["recall_at_1"].low > 0 and diff["recall_at_1"].excludes_zero()
    same = uncertainty.paired_difference(good, good, replicates=300)
    assert same["f1_max"].mean == 0 and not same["f1_max"].excludes_zero()
    with pytest.raises(DataError, match="same seeds"):
        uncertainty.paired_difference(good, bad[:2])


def test_compare_prints_paired_differences_and_a_verdict(tmp_path, capsys) -> None:
    from safl_bench.cli import main
    from safl_bench.records import write_record

    for name, skill in (("good", 0.9), ("bad", 0.3)):
        for seed in (0, 1):
            write_record(tmp_path, scored_record(name, seed=seed, skill=skill))
    assert main(["compare", "--method", "good", "--method", "bad", "--results", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "seeds 0, 1" in out and "A - B" in out
    assert "verdict: A better on" in out and "recall_at_1" in out.split("verdict:")[1]
    assert main(["compare", "--method", "good", "--results", str(tmp_path)]) == 2


def test_a_method_that_reports_no_match_has_zero_measures_and_an_interval() -> None:
    o = metrics.outcomes([-np.inf] * 20, [False] * 20, [True] * 20)
    cell = uncertainty.bootstrap([o], replicates=50)
    assert cell["recall_at_1"].mean == 0.0 and cell["f1_max"].high == 0.0
    assert np.isnan(cell["auc"].mean)  # one class only, as the metrics say (None)


def test_block_measures_are_the_weighted_measures_of_the_block_weights() -> None:
    o = random_outcomes(3)
    fused = uncertainty.block_measures(o, 40, np.random.default_rng(9))
    weights = uncertainty.block_weights(len(o.confidence), 40, np.random.default_rng(9))
    direct = uncertainty.weighted_measures(o, weights)
    assert fused.keys() == direct.keys()
    for name in direct:
        np.testing.assert_array_equal(fused[name], direct[name], err_msg=name)
