"""Hand-computed values of the bootstrap (`safl_bench.evaluation.uncertainty`) and of the
leaderboard's bold / "≈" rule (`safl_bench.leaderboard.intervals`) on small made-up cases:
ties in confidence, one seed, one query, one class, the paired difference (issue #37, item 5).

Exact values where they are determined (a point estimate is the metric's value; every resample
of one query is that query), properties where they are random (an interval holds its point, is
the same for the same seed, has width zero when every resample is equal). No file is read."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from record_factory import make_record, random_outcomes

from safl_bench.errors import DataError
from safl_bench.evaluation import metrics, uncertainty
from safl_bench.evaluation.metrics import AMBIGUOUS, CORRECT, WRONG, Outcomes
from safl_bench.evaluation.uncertainty import Interval, Sample
from safl_bench.leaderboard import intervals
from safl_bench.leaderboard.intervals import BEST, TIED, Ranked
from safl_bench.records import ResultRecord, mode_result_from_evaluation

#: `uncertainty` measure -> the `metrics.Metrics` field it must equal at unit weights
METRIC_OF = {"recall_at_100_precision": "recall_at_100",
             "recall_at_100_precision_of_correct": "recall_at_100_of_correct",
             "f1_max": "f1_max", "f1_max_of_correct": "f1_max_of_correct",
             "extended_precision": "extended_precision",
             "extended_precision_of_correct": "extended_precision_of_correct",
             "auc": "roc_auc", "authors_recall_at_99p": "authors_recall_at_99p",
             "recall_at_1": "recall_at_1"}


def tied_case() -> Outcomes:
    """Six queries, all with a true place; confidences tied across a correct and a wrong match
    twice (the correct one first in query order, so ignoring a tie moves the thresholds):

    ====  ====  =======  =====
    q     conf  label    rank
    ====  ====  =======  =====
    0     3     correct  1
    1     2     correct  1
    2     2     wrong    3
    3     1     correct  1
    4     1     wrong    7
    5     0     wrong    12
    ====  ====  =======  =====
    """
    return metrics.outcomes([3.0, 2.0, 2.0, 1.0, 1.0, 0.0], [1, 1, 0, 1, 0, 0], [True] * 6,
                            true_rank=[1, 1, 3, 1, 7, 12])


#: Hand-computed. P = 6, C = 3; thresholds 3, 2, 1, 0 give (TP, FP) = (1, 0), (2, 1), (3, 2),
#: (3, 3). AUC: positive 3 beats all three negatives (3), positive 2 beats 1 and 0 and ties 2
#: (2.5), positive 1 beats 0 and ties 1 (1.5): 7 of 9 pairs (a tie counted in full: 8/9).
TIED_VALUES = {
    "recall_at_100_precision": 1 / 6,
    "recall_at_100_precision_of_correct": 1 / 3,
    "f1_max": 6 / 11,  # 2 TP / (TP + FP + P) at threshold 1
    "f1_max_of_correct": 3 / 4,  # 2 TP / (TP + FP + C) at threshold 1
    "extended_precision": (1 + 1 / 6) / 2,  # precision 1 at the most confident threshold
    "extended_precision_of_correct": (1 + 1 / 3) / 2,
    "auc": 7 / 9,
    "authors_recall_at_99p": 1 / 3,  # only threshold 3 has precision >= 0.99
    "recall_at_1": 3 / 6,
    "recall_at_5": 4 / 6,
    "recall_at_10": 5 / 6,
}


def mixed_case() -> Outcomes:
    """Every kind of query: correct, ambiguous, wrong, no match reported, a wrong match on a
    query without a true place (the most confident match), and a query without a candidate
    (left out of every measure, though its confidence 5 is the highest).

    ====  ====  =========  ==========  =========  ====
    q     conf  label      true place  candidate  rank
    ====  ====  =========  ==========  =========  ====
    0     2     correct    yes         yes        1
    1     1.5   ambiguous  yes         yes        2
    2     1     wrong      yes         yes        6
    3     -inf  (none)     yes         yes        11
    4     2.5   correct    yes         yes        1
    5     3     wrong      no          yes        0
    6     5     wrong      no          no         0
    ====  ====  =========  ==========  =========  ====
    """
    return metrics.outcomes([2.0, 1.5, 1.0, -np.inf, 2.5, 3.0, 5.0],
                            [1, 0, 0, 0, 1, 0, 0], [1, 1, 1, 1, 1, 0, 0],
                            ambiguous=[0, 1, 0, 0, 0, 0, 0], has_candidate=[1, 1, 1, 1, 1, 1, 0],
                            true_rank=[1, 2, 6, 11, 1, 0, 0])


#: Hand-computed. P = 5, C = 2; thresholds 3, 2.5, 2, 1.5, 1 give (TP, FP) = (0, 1), (1, 1),
#: (2, 1), (2, 1) (the ambiguous match is neither), (2, 2). AUC: positives 2.5 and 2 each beat
#: the wrong 1 and the unanswered query, never the wrong 3: 4 of 6 pairs.
MIXED_VALUES = {
    "recall_at_100_precision": 0.0,  # the most confident match is wrong
    "recall_at_100_precision_of_correct": 0.0,
    "f1_max": 1 / 2,  # 2 * 2 / (3 + 5) at threshold 2
    "f1_max_of_correct": 4 / 5,  # 2 * 2 / (3 + 2)
    "extended_precision": 0.0,
    "extended_precision_of_correct": 0.0,
    "auc": 2 / 3,
    "authors_recall_at_99p": 0.0,
    "recall_at_1": 2 / 5,
    "recall_at_5": 3 / 5,
    "recall_at_10": 4 / 5,
}


#: the exact messages (a mutant that changes one is caught)
SAME_SEEDS = r"^a paired comparison needs the same seeds on both sides, got {} and {}$"
SAME_QUERIES = r"^seed #0: the two sides were not scored on the same queries$"


def point(o: Outcomes) -> dict[str, float]:
    return {k: float(v[0]) for k, v in uncertainty.weighted_measures(o, np.ones((1, len(o.confidence)))).items()}


def assert_values(got: dict[str, float], expected: dict[str, float]) -> None:
    assert set(got) == set(expected)
    for name, value in expected.items():
        if math.isnan(value):
            assert math.isnan(got[name]), name
        else:
            assert got[name] == pytest.approx(value, rel=1e-12, abs=1e-15), name


def assert_agrees_with_metrics(o: Outcomes, got: dict[str, float]) -> None:
    m = metrics.evaluate_outcomes(o, recall_at=(5, 10))
    for ours, theirs in METRIC_OF.items():
        expected = getattr(m, theirs)
        if expected is None:
            assert math.isnan(got[ours]), ours
        else:
            assert got[ours] == pytest.approx(expected, rel=1e-12, abs=1e-15), ours
    if o.true_rank is not None:
        assert got["recall_at_5"] == pytest.approx(m.recall_at_n[5])
        assert got["recall_at_10"] == pytest.approx(m.recall_at_n[10])


# --------------------------------------------------------------------------- point values


@pytest.mark.parametrize(("case", "values"), [(tied_case, TIED_VALUES), (mixed_case, MIXED_VALUES)])
def test_the_measures_at_unit_weights_are_the_hand_computed_metrics(case, values) -> None:
    o = case()
    got = point(o)
    assert_values(got, values)
    assert_agrees_with_metrics(o, got)  # the metric's AUC is roc_auc_score's: ties count half
    assert_values({k: v.mean for k, v in uncertainty.bootstrap([o], replicates=20).items()}, values)


def test_auc_counts_a_tied_correct_and_wrong_pair_half() -> None:
    # one correct and one wrong match at the same confidence: 1/2, not 1 (nor 0)
    o = metrics.outcomes([1.0, 1.0], [1, 0], [True, True])
    assert point(o)["auc"] == 0.5 == metrics.evaluate_outcomes(o).roc_auc
    # ... and its interval: every resample of two queries (one block) is the same two queries
    cell = uncertainty.bootstrap([o], replicates=30)["auc"]
    assert (cell.mean, cell.low, cell.high) == (0.5, 0.5, 0.5)
    # unanswered queries are tied below every match: an answered wrong one is no tie with them
    o = metrics.outcomes([1.0, -np.inf, -np.inf, 0.0], [1, 0, 0, 0], [True, True, True, False])
    assert point(o)["auc"] == 1.0 == metrics.evaluate_outcomes(o).roc_auc


def test_the_authors_precision_is_reached_at_exactly_99_of_100() -> None:
    # the most confident match wrong, then 99 correct: precision 0.99 only at the lowest
    # threshold, which the authors' reading takes (>= 0.99): all 99 correct matches
    o = metrics.outcomes(np.arange(100, 0, -1.0), [0] + [1] * 99, [True] * 100)
    got = point(o)
    assert got["authors_recall_at_99p"] == 1.0 == metrics.evaluate_outcomes(o).authors_recall_at_99p
    assert got["recall_at_100_precision"] == 0.0 and got["f1_max"] == pytest.approx(198 / 200)
    assert_agrees_with_metrics(o, got)


def test_the_query_order_of_tied_confidences_changes_nothing() -> None:
    o = tied_case()
    assert o.true_rank is not None
    order = np.array([2, 1, 0, 4, 3, 5])  # each tied wrong match before its correct one
    swapped = Outcomes(o.confidence[order], o.label[order], o.has_true_place[order],
                       o.has_candidate[order], o.true_rank[order])
    assert_values(point(swapped), TIED_VALUES)


def test_weights_count_a_query_that_many_times() -> None:
    # the tied case, query 0 twice and query 5 not at all: P = 6, C = 4; thresholds 3, 2, 1 give
    # (TP, FP) = (2, 0), (3, 1), (4, 2). AUC: negatives 2 and 1 (weight 1 each); positive 3
    # (weight 2) beats both: 4; positive 2 beats 1, ties 2: 1.5; positive 1 ties 1: 0.5; of 4 * 2
    got = uncertainty.weighted_measures(tied_case(), np.array([[2, 1, 1, 1, 1, 0]]))
    assert got["recall_at_100_precision"][0] == pytest.approx(2 / 6)
    assert got["recall_at_100_precision_of_correct"][0] == pytest.approx(2 / 4)
    assert got["recall_at_1"][0] == pytest.approx(4 / 6)
    assert got["f1_max"][0] == pytest.approx(8 / 12)
    assert got["f1_max_of_correct"][0] == pytest.approx(8 / 10)
    assert got["auc"][0] == pytest.approx(6 / 8)
    assert got["authors_recall_at_99p"][0] == pytest.approx(2 / 4)
    assert got["recall_at_5"][0] == pytest.approx(5 / 6)  # ranks 1 (twice), 1, 3, 1
    assert got["recall_at_10"][0] == pytest.approx(6 / 6)  # and 7


def test_rows_of_weights_are_replicates_and_a_draw_without_a_positive_is_undefined() -> None:
    o = tied_case()
    w = np.array([[1, 1, 1, 1, 1, 1], [0, 0, 0, 0, 0, 0], [0, 0, 1, 0, 1, 1], [1, 0, 0, 0, 0, 0]])
    got = uncertainty.weighted_measures(o, w)
    assert_values({k: v[0] for k, v in got.items()}, TIED_VALUES)
    assert all(math.isnan(v[1]) for k, v in got.items()), "no query drawn"
    # only wrong matches drawn: every recall 0, AUC of one class undefined
    assert got["recall_at_1"][2] == 0.0 and got["f1_max"][2] == 0.0 and math.isnan(got["auc"][2])
    assert got["extended_precision"][2] == 0.0 and got["f1_max_of_correct"][2] == 0.0
    # only the correct query 0 drawn: everything 1, AUC undefined
    assert got["recall_at_100_precision"][3] == 1.0 and got["extended_precision"][3] == 1.0
    assert got["authors_recall_at_99p"][3] == 1.0 and math.isnan(got["auc"][3])


def test_one_query() -> None:
    def alone(conf: float, correct: bool) -> Outcomes:
        return metrics.outcomes([conf], [correct], [True], true_rank=[1 if correct else 4])

    right = point(alone(2.0, True))
    assert_values(right, {**dict.fromkeys(TIED_VALUES, 1.0), "auc": float("nan")})
    assert_agrees_with_metrics(alone(2.0, True), right)
    wrong = point(alone(2.0, False))
    assert_values(wrong, {**dict.fromkeys(TIED_VALUES, 0.0), "auc": float("nan"),
                          "recall_at_5": 1.0, "recall_at_10": 1.0})
    assert_agrees_with_metrics(alone(2.0, False), wrong)
    silent = point(alone(-np.inf, False))
    assert_values(silent, {**dict.fromkeys(TIED_VALUES, 0.0), "auc": float("nan"),
                           "recall_at_5": 1.0, "recall_at_10": 1.0})
    # one seed of one query: every resample is that query, so every interval has width zero
    cells = uncertainty.bootstrap([alone(2.0, True)], replicates=25)
    for name, cell in cells.items():
        if name == "auc":
            assert math.isnan(cell.mean) and cell.format() == "n/a"
        else:
            assert (cell.mean, cell.low, cell.high) == (1.0, 1.0, 1.0), name
        assert (cell.n_seeds, cell.n_queries) == (1, 1)


def test_one_class_and_no_positive() -> None:
    every = metrics.outcomes([3.0, 2.0, 1.0], [1, 1, 1], [1, 1, 1], true_rank=[1, 1, 1])
    got = point(every)
    assert_values(got, {**dict.fromkeys(TIED_VALUES, 1.0), "auc": float("nan")})
    assert_agrees_with_metrics(every, got)
    # no query with a true place: recall (and so every measure but the AUC) undefined, where
    # the metrics refuse; the AUC of wrong matches only, one class, too
    none = metrics.outcomes([3.0, 2.0, -np.inf], [0, 0, 0], [0, 0, 0], true_rank=[0, 0, 0])
    with pytest.raises(metrics.NoPositivesError):
        metrics.evaluate_outcomes(none)
    assert all(math.isnan(v) for v in point(none).values())
    cells = uncertainty.bootstrap([none], replicates=10)
    assert all(c.format() == "n/a" and math.isnan(c.low) for c in cells.values())


def test_recall_at_n_counts_a_true_place_ranked_exactly_n() -> None:
    o = metrics.outcomes([4.0, 3.0, 2.0, 1.0, 0.5], [1, 0, 0, 0, 0], [True] * 4 + [False],
                         true_rank=[5, 6, 10, 11, 0])
    got = point(o)
    assert (got["recall_at_5"], got["recall_at_10"]) == (1 / 4, 3 / 4)
    assert_agrees_with_metrics(o, got)


def test_without_ranks_there_is_no_recall_at_5_or_10() -> None:
    o = tied_case()
    bare = Outcomes(o.confidence, o.label, o.has_true_place, o.has_candidate)
    expected = {k: v for k, v in TIED_VALUES.items() if k not in ("recall_at_5", "recall_at_10")}
    assert_values(point(bare), expected)
    assert set(uncertainty.bootstrap([bare], replicates=5)) == set(expected)
    assert set(uncertainty.bootstrap([o], replicates=5)) == set(uncertainty.measure_names())


def test_a_query_without_a_candidate_changes_no_point_value() -> None:
    o = mixed_case()
    assert o.true_rank is not None
    keep = o.has_candidate
    dropped = Outcomes(o.confidence[keep], o.label[keep], o.has_true_place[keep],
                       o.has_candidate[keep], o.true_rank[keep])
    assert_values(point(dropped), MIXED_VALUES)
    # ... whatever its label and confidence
    as_correct = Outcomes(o.confidence, np.where(keep, o.label, CORRECT).astype(np.int8),
                          o.has_true_place, o.has_candidate, o.true_rank)
    assert_values(point(as_correct), MIXED_VALUES)


def test_an_ambiguous_match_is_neither_a_hit_nor_a_miss() -> None:
    o = mixed_case()
    # query 1 (ambiguous, 1.5) made wrong: one more FP below threshold 2 (f1 unchanged) and one
    # more negative for the AUC, below both positives: 6 of 8
    label = o.label.copy()
    label[1] = WRONG
    got = point(Outcomes(o.confidence, label, o.has_true_place, o.has_candidate, o.true_rank))
    assert got["auc"] == pytest.approx(6 / 8) and got["f1_max"] == pytest.approx(1 / 2)
    assert got["f1_max_of_correct"] == pytest.approx(4 / 5)
    assert label[1] != AMBIGUOUS and point(o)["auc"] == pytest.approx(2 / 3)


# --------------------------------------------------------------------------- the bootstrap


def reference_replicates(seeds: list[Outcomes], replicates: int) -> dict[str, np.ndarray]:
    """The two-level block bootstrap as the module docstring describes it, written out: one
    generator seeded 20261202; first each replicate's seed draws (none with one seed), then for
    each seed in order, one circular resample (blocks of 10 queries) per draw of it."""
    rng = np.random.default_rng(20261202)
    k = len(seeds)
    draws = np.zeros((replicates, 1), np.int64) if k == 1 else rng.integers(0, k, (replicates, k))
    total: dict[str, np.ndarray] = {}
    for s, o in enumerate(seeds):
        rows = [r for r in range(replicates) for d in draws[r] if d == s]
        if not rows:
            continue
        n = len(o.confidence)
        block = min(10, n)
        starts = rng.integers(0, n, (len(rows), -(-n // block)))
        w = np.zeros((len(rows), n))
        for i, row in enumerate(starts):
            picked = np.concatenate([(b + np.arange(block)) % n for b in row])[:n]
            np.add.at(w[i], picked, 1)
        for name, values in uncertainty.weighted_measures(o, w).items():
            acc = total.setdefault(name, np.zeros(replicates))
            for i, r in enumerate(rows):
                acc[r] += values[i]
    return {name: v / k for name, v in total.items()}


@pytest.mark.parametrize(("n_seeds", "replicates"), [(1, 40), (3, 40), (3, 2), (5, 1)])
def test_the_replicates_are_the_documented_two_level_block_bootstrap(n_seeds: int,
                                                                     replicates: int) -> None:
    # (few replicates: some seed is drawn by none, and the later seeds still are resampled)
    seeds = [random_outcomes(s, n=23 + s) for s in range(n_seeds)]
    got = uncertainty.sample(seeds, replicates=replicates)
    expected = reference_replicates(seeds, replicates)
    assert set(got.values) == set(expected)
    for name in expected:
        np.testing.assert_allclose(got.values[name], expected[name], rtol=1e-12, err_msg=name)
    assert got.n_seeds == n_seeds and got.n_queries == 23
    # the interval: the 2.5 % and 97.5 % quantiles of the finite replicates, around the point
    for name, cell in got.intervals().items():
        finite = expected[name][np.isfinite(expected[name])]
        assert cell.low == pytest.approx(np.quantile(finite, 0.025)), name
        assert cell.high == pytest.approx(np.quantile(finite, 0.975)), name
        assert cell.mean == pytest.approx(np.mean([point(o)[name] for o in seeds])), name


def test_the_documented_constants() -> None:
    assert (uncertainty.REPLICATES, uncertainty.BLOCK, uncertainty.LEVEL) == (1000, 10, 0.95)
    assert uncertainty.BOOTSTRAP_SEED == 20261202
    assert uncertainty.sample([tied_case()]).values["auc"].shape == (1000,)
    # default blocks of ten: 25 queries are three blocks, each a run of consecutive queries
    w = uncertainty.block_weights(25, 1, np.random.default_rng(3))
    assert w.shape == (1, 25) and w.sum() == 25
    starts = np.random.default_rng(3).integers(0, 25, (1, 3))[0]
    expected = np.zeros(25, np.int64)
    for k, b in enumerate(starts):
        np.add.at(expected, (b + np.arange(10 if k < 2 else 5)) % 25, 1)
    np.testing.assert_array_equal(w[0], expected)


def test_block_weights_of_a_short_sample_and_of_none() -> None:
    # fewer queries than a block: one block of all of them, every query once
    np.testing.assert_array_equal(uncertainty.block_weights(4, 3, np.random.default_rng(0)),
                                  np.ones((3, 4)))
    np.testing.assert_array_equal(uncertainty.block_weights(5, 2, np.random.default_rng(0), block=0),
                                  uncertainty.block_weights(5, 2, np.random.default_rng(0), block=1))
    np.testing.assert_array_equal(uncertainty.block_weights(1, 2, np.random.default_rng(0)),
                                  np.ones((2, 1)))
    with pytest.raises(DataError, match=r"^cannot resample an empty set of queries$"):
        uncertainty.block_weights(0, 3, np.random.default_rng(0))
    empty = Outcomes(np.zeros(0), np.zeros(0, np.int8), np.zeros(0, bool), np.zeros(0, bool))
    with pytest.raises(DataError, match=r"^cannot resample an empty set of queries$"):
        uncertainty.block_measures(empty, 3, np.random.default_rng(0))
    # block 1: single queries, the same draws as blocks of one
    o = tied_case()
    one = uncertainty.block_measures(o, 7, np.random.default_rng(5), block=1)
    direct = uncertainty.weighted_measures(o, uncertainty.block_weights(6, 7, np.random.default_rng(5), block=1))
    for name in direct:
        np.testing.assert_array_equal(one[name], direct[name], err_msg=name)
    zero = uncertainty.block_measures(o, 7, np.random.default_rng(5), block=0)
    for name in direct:
        np.testing.assert_array_equal(zero[name], direct[name], err_msg=name)


def test_two_seeds_of_one_query_resample_the_seeds() -> None:
    # seed 0 answers its query, seed 1 misses it: each replicate is the mean of two seed draws,
    # 0, 1/2 or 1 (about 1/4, 1/2, 1/4 of them); the point is 1/2, the interval [0, 1]
    seeds = [metrics.outcomes([1.0], [1], [1]), metrics.outcomes([1.0], [0], [1])]
    s = uncertainty.sample(seeds)
    values = s.values["recall_at_1"]
    assert set(np.unique(values)) == {0.0, 0.5, 1.0}
    share = {v: float(np.mean(values == v)) for v in (0.0, 0.5, 1.0)}
    assert 0.2 < share[0.0] < 0.3 and 0.45 < share[0.5] < 0.55 and 0.2 < share[1.0] < 0.3
    cell = s.intervals()["recall_at_1"]
    assert (cell.mean, cell.low, cell.high, cell.n_seeds, cell.n_queries) == (0.5, 0.0, 1.0, 2, 1)
    assert math.isnan(s.points["auc"])  # one class on each seed
    # the same seeds, the same interval (a fixed generator)
    again = uncertainty.bootstrap(seeds)
    assert all(again[k] == v for k, v in s.intervals().items() if k != "auc")


def test_an_interval_holds_its_point_and_is_deterministic() -> None:
    seeds = [tied_case(), mixed_case()]
    first = uncertainty.bootstrap(seeds, replicates=200)
    assert first == uncertainty.bootstrap(seeds, replicates=200)
    # the replicates asked for, not the default (with more queries than a block: they differ)
    big = [random_outcomes(s, n=40) for s in (0, 1)]
    few = uncertainty.bootstrap(big, replicates=30)
    assert few == uncertainty.sample(big, replicates=30).intervals() != uncertainty.bootstrap(big)
    for name, cell in first.items():
        assert cell.low <= cell.mean <= cell.high, name
        assert cell.mean == pytest.approx((TIED_VALUES[name] + MIXED_VALUES[name]) / 2), name
        assert (cell.n_seeds, cell.n_queries) == (2, 6)


def test_the_interval_of_replicates_drops_undefined_ones() -> None:
    truth = ((41, b"\x00"),)
    values = np.r_[np.arange(41.0), np.nan, np.nan]
    s = Sample({"m": 20.0, "u": float("nan"), "e": 1.0},
               {"m": values, "u": values, "e": np.full(5, np.nan)}, truth)
    got = s.intervals()
    assert (got["m"].mean, got["m"].n_seeds, got["m"].n_queries) == (20.0, 1, 41)
    assert (got["m"].low, got["m"].high) == pytest.approx((1.0, 39.0))  # 2.5 %, 97.5 % of 0..40
    assert math.isnan(got["u"].mean) and math.isnan(got["u"].low) and math.isnan(got["u"].high)
    assert got["e"].mean == 1.0 and math.isnan(got["e"].low) and math.isnan(got["e"].high)
    assert got["e"].format() == "1.0 [n/a]"


def test_sample_refuses_no_seed() -> None:
    with pytest.raises(DataError, match=r"^no seed to compute an interval from$"):
        uncertainty.sample([])
    with pytest.raises(DataError, match=SAME_SEEDS.format(0, 0)):
        uncertainty.paired_difference([], [])


# --------------------------------------------------------------------------- paired differences


def answered(n: int, correct: bool) -> Outcomes:
    """n queries with a true place, all answered correctly or all wrongly (distinct confidences)."""
    return metrics.outcomes(np.arange(n, 0, -1.0), [correct] * n, [True] * n,
                            true_rank=[1 if correct else 20] * n)


def test_a_method_right_on_every_query_beats_one_wrong_on_every_query_in_every_resample() -> None:
    good = [answered(12, True), answered(12, True)]
    bad = [answered(12, False), answered(12, False)]
    diff = uncertainty.paired_difference(good, bad, replicates=50)
    for name in ("recall_at_1", "f1_max", "recall_at_100_precision", "extended_precision",
                 "recall_at_5", "authors_recall_at_99p"):
        assert diff[name] == Interval(1.0, 1.0, 1.0, 2, 12), name
        assert diff[name].excludes_zero()
    reverse = uncertainty.paired_difference(bad, good, replicates=50)
    assert reverse["recall_at_1"] == Interval(-1.0, -1.0, -1.0, 2, 12)
    assert reverse["recall_at_1"].excludes_zero()
    # one class on both sides: the AUC difference is undefined, never resolved
    assert math.isnan(diff["auc"].mean) and not diff["auc"].excludes_zero()
    assert diff["recall_at_10"].format(100) == "100.0 [100.0, 100.0]"  # rank 1 against rank 20


def test_the_paired_difference_is_the_difference_of_the_same_resamples() -> None:
    a = [tied_case(), tied_case()]
    o = tied_case()
    b = [Outcomes(o.confidence, np.full(6, WRONG, np.int8), o.has_true_place, o.has_candidate,
                  o.true_rank)] * 2
    sa, sb = uncertainty.sample(a, replicates=60), uncertainty.sample(b, replicates=60)
    diff = uncertainty.paired_difference(a, b, replicates=60)
    for name, cell in diff.items():
        d = sa.values[name] - sb.values[name]
        d = d[np.isfinite(d)]
        if name == "auc":  # b is one class: no difference
            assert math.isnan(cell.mean) and math.isnan(cell.low)
            continue
        assert cell.mean == pytest.approx(TIED_VALUES[name] - point(b[0])[name]), name
        assert (cell.low, cell.high) == tuple(np.quantile(d, [0.025, 0.975])), name
    # recall@1 of b is 0 in every resample, so the difference is a's own replicates
    np.testing.assert_array_equal(sb.values["recall_at_1"], 0.0)
    assert diff["recall_at_1"].low == sa.intervals()["recall_at_1"].low > 0
    # a method against itself: zero in every resample, width zero, not resolved
    same = uncertainty.paired_difference(a, a, replicates=60)
    for name, cell in same.items():
        if name != "auc" or not math.isnan(cell.mean):
            assert (cell.mean, cell.low, cell.high) == (0.0, 0.0, 0.0), name
            assert not cell.excludes_zero()


def test_a_paired_difference_needs_the_same_seeds_and_queries() -> None:
    a = [tied_case()]
    with pytest.raises(DataError, match=SAME_SEEDS.format(1, 2)):
        uncertainty.paired_difference(a, a * 2)
    with pytest.raises(DataError, match=SAME_SEEDS.format(1, 2)):
        uncertainty.sample(a).minus(uncertainty.sample(a * 2))
    o = tied_case()
    other_positives = Outcomes(o.confidence, np.where(np.arange(6) == 0, WRONG, o.label).astype(np.int8),
                               np.arange(6) != 0, o.has_candidate, None)
    with pytest.raises(DataError, match=SAME_QUERIES):
        uncertainty.paired_difference(a, [other_positives])
    with pytest.raises(DataError, match=SAME_QUERIES):
        uncertainty.paired_difference(a, [answered(7, True)])
    # the same queries with other answers pair; measures only one side has are left out
    bare = Outcomes(o.confidence, o.label, o.has_true_place, o.has_candidate)
    assert set(uncertainty.paired_difference(a, [bare], replicates=5)) == set(METRIC_OF)


def test_excludes_zero_and_format() -> None:
    assert Interval(0.1, 0.05, 0.2, 1, 1).excludes_zero()
    assert Interval(-0.1, -0.2, -0.05, 1, 1).excludes_zero()
    assert not Interval(0.1, 0.0, 0.2, 1, 1).excludes_zero()  # touching 0 is not excluding it
    assert not Interval(-0.1, -0.2, 0.0, 1, 1).excludes_zero()
    assert not Interval(0.0, -0.1, 0.1, 1, 1).excludes_zero()
    nan = float("nan")
    assert not Interval(0.1, nan, nan, 1, 1).excludes_zero()
    assert Interval(0.5, 0.25, 0.75, 1, 1).format(100) == "50.0 [25.0, 75.0]"
    assert Interval(0.123, 0.1, 0.2, 1, 1).format() == "0.1 [0.1, 0.2]"
    assert Interval(-0.5, -1.0, 0.125, 1, 1).format(1, 3) == "-0.500 [-1.000, 0.125]"
    assert Interval(-0.0001, -0.0002, 0.0, 1, 1).format(100) == "0.0 [0.0, 0.0]"  # no "-0.0"
    assert Interval(0.5, nan, nan, 1, 1).format(100, 2) == "50.00 [n/a]"
    assert Interval(nan, nan, nan, 1, 1).format() == "n/a"


# --------------------------------------------------------------------------- bold and ≈


def record(method: str, o: Outcomes, seed: int = 0) -> ResultRecord:
    mode = mode_result_from_evaluation(metrics.evaluate_outcomes(o), o)
    return dataclasses.replace(make_record(method, seed=seed),
                               results={"sequence": mode, "single_frame": mode})


def cell(index: int, records: list[ResultRecord], shown: float | None = None,
         measure: str | None = "recall_at_1", mode: str = "sequence") -> Ranked:
    mean = float(np.mean([r.results[mode].metrics.recall_at_1 for r in records]))
    return Ranked(index, mean, mean if shown is None else shown, tuple(records), mode, measure)


def flipped(o: Outcomes, queries: list[int]) -> Outcomes:
    """`o` with the correct matches of `queries` made wrong (one seed's answers, a little worse)."""
    label = o.label.copy()
    label[queries] = WRONG
    return Outcomes(o.confidence, label, o.has_true_place, o.has_candidate, o.true_rank)


GOOD = [record("good", answered(20, True), seed) for seed in (0, 1)]
BAD = [record("bad", answered(20, False), seed) for seed in (0, 1)]
NEAR = [record("near", flipped(answered(20, True), [4]), seed) for seed in (0, 1)]


def test_a_clear_winner_is_bold_alone() -> None:
    assert intervals.rank([cell(0, GOOD), cell(1, BAD)], "higher") == {0: BEST}
    assert intervals.rank([cell(3, BAD), cell(7, GOOD)], "higher") == {7: BEST}
    # lower is better: the lower mean, beyond the noise, is the best
    assert intervals.rank([cell(0, GOOD), cell(1, BAD)], "lower") == {1: BEST}


def test_overlapping_cells_are_tied_for_best() -> None:
    # one query of twenty answered wrongly: not resolved (a resample may leave it out)
    assert intervals.rank([cell(0, GOOD), cell(1, NEAR)], "higher") == {0: TIED, 1: TIED}
    # the third, beyond the noise of both, is not marked
    got = intervals.rank([cell(0, BAD), cell(1, NEAR), cell(2, GOOD)], "higher")
    assert got == {2: TIED, 1: TIED}
    # the best alone beyond the noise of every other is bold
    assert intervals.rank([cell(0, BAD), cell(1, GOOD), cell(2, BAD)], "higher") == {1: BEST}


def test_no_mark_for_a_single_cell_or_all_equal_values() -> None:
    assert intervals.rank([cell(0, GOOD)], "higher") == {}
    assert intervals.rank([], "higher") == {}
    assert intervals.rank([cell(0, GOOD), cell(1, BAD, shown=1.0)], "higher") == {}
    # equal as shown to the best: tied, whatever the records say
    got = intervals.rank([cell(0, GOOD), cell(1, BAD, shown=1.0), cell(2, BAD)], "higher")
    assert got == {0: TIED, 1: TIED}
    # ... and the cells below them are still compared with the best
    got = intervals.rank([cell(0, GOOD), cell(1, BAD, shown=1.0), cell(2, NEAR)], "higher")
    assert got == {0: TIED, 1: TIED, 2: TIED}


def test_an_order_the_paired_difference_contradicts_is_not_resolved() -> None:
    # shown values that rank BAD first: the difference excludes 0, the wrong way
    got = intervals.rank([cell(0, GOOD, shown=0.1), cell(1, BAD, shown=0.9)], "higher")
    assert got == {0: TIED, 1: TIED}


def test_the_best_is_bold_only_when_its_point_difference_is_positive(monkeypatch) -> None:
    # an interval that excludes 0 around a point difference of 0 (a percentile interval need
    # not hold its point) or below it does not resolve the order
    for mean in (0.0, -0.1):
        monkeypatch.setattr(intervals, "_difference", lambda a, b, m=mean: Interval(m, 0.1, 0.2, 1, 9))
        assert intervals.rank([cell(0, GOOD), cell(1, BAD)], "higher") == {0: TIED, 1: TIED}
    monkeypatch.setattr(intervals, "_difference", lambda a, b: Interval(0.01, 0.1, 0.2, 1, 9))
    assert intervals.rank([cell(0, GOOD), cell(1, BAD)], "higher") == {0: BEST}


def test_a_difference_that_cannot_be_computed_is_a_tie() -> None:
    # no interval for the measure
    assert intervals.rank([cell(0, GOOD, measure=None), cell(1, BAD)], "higher") == {0: TIED, 1: TIED}
    # no seed in common
    assert intervals.rank([cell(0, GOOD[:1]), cell(1, BAD[1:])], "higher") == {0: TIED, 1: TIED}
    # records without per-query outcomes (metrics version 1)
    plain = [make_record("old", seed=s, recall_at_1=0.1) for s in (0, 1)]
    assert intervals.cell_sample(plain, "sequence") is None
    old = Ranked(1, 0.1, 0.1, tuple(plain), "sequence", "recall_at_1")
    assert intervals.rank([cell(0, GOOD), old], "higher") == {0: TIED, 1: TIED}
    assert intervals.rank([old, cell(0, BAD)], "higher") == {1: TIED, 0: TIED}
    # not scored on the same queries
    other = [record("other", answered(21, False), s) for s in (0, 1)]
    assert intervals.rank([cell(0, GOOD), cell(1, other)], "higher") == {0: TIED, 1: TIED}


def test_cells_are_compared_on_the_seeds_both_have() -> None:
    # GOOD on seeds 0 and 1, BAD on seed 1 alone: compared on seed 1, resolved
    assert intervals.rank([cell(0, GOOD), cell(1, BAD[1:])], "higher") == {0: BEST}
    diff = intervals._difference(cell(0, GOOD), cell(1, BAD[1:]))
    assert diff == Interval(1.0, 1.0, 1.0, 1, 20)
    assert intervals._difference(cell(0, GOOD, measure=None), cell(1, BAD)) is None


def test_a_cells_bootstrap_is_computed_once_and_kept_for_its_records(monkeypatch) -> None:
    first = intervals.cell_sample(GOOD, "sequence")
    assert first is not None and first.n_seeds == 2 and first.n_queries == 20
    assert intervals.cell_sample(GOOD[::-1], "sequence") is first  # seed order, not list order
    assert intervals.cell_sample(GOOD, "single_frame") is not first
    other = intervals.cell_sample(BAD, "sequence")  # another cell of as many seeds: kept beside
    assert intervals.cell_sample(GOOD, "sequence") is first
    assert intervals.cell_sample(BAD, "sequence") is other
    assert first.points["recall_at_1"] == 1.0 and math.isnan(first.points["auc"])
    # an entry whose records are not these (an id reused by another object) is not theirs
    fresh = [record("fresh", answered(20, False), 0)]
    stale = uncertainty.sample([answered(20, True)], replicates=3)
    monkeypatch.setitem(intervals._CACHE, ("sequence", id(fresh[0])), ((GOOD[0],), stale))
    got = intervals.cell_sample(fresh, "sequence")
    assert got is not stale and got is not None and got.points["recall_at_1"] == 0.0
    # the cache is emptied when full
    monkeypatch.setattr(intervals, "_CACHE", {})
    monkeypatch.setattr(intervals, "_CACHE_LIMIT", 2)
    for records in (GOOD, BAD, NEAR):
        intervals.cell_sample(records, "sequence")
    assert len(intervals._CACHE) == 1


def test_without_intervals_is_scoped() -> None:
    assert intervals.enabled()
    with intervals.without_intervals():
        assert not intervals.enabled()
        with intervals.without_intervals():
            assert not intervals.enabled()
        assert not intervals.enabled()
    assert intervals.enabled()
    with pytest.raises(RuntimeError), intervals.without_intervals():
        raise RuntimeError
    assert intervals.enabled()
