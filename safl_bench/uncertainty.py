"""Uncertainty of a measure: a 95 % interval over the noise seeds AND the finite set of queries,
and paired differences between methods, from the per-query outcomes records hold.

Choices, and why:

* **Two-level (hierarchical) bootstrap.** One replicate draws the cell's seeds with
  replacement (the query noise: a new seed is a new draw of the noise), then, for each drawn
  seed, resamples that seed's queries; the replicate's value is the mean over its drawn seeds of
  the measure computed on the resampled queries, exactly as `safl_bench.metrics` defines it
  (`measure_names`). With one seed (a fixed split, nothing random) only the queries are
  resampled. This is the standard nonparametric bootstrap for a two-stage sample (Davison &
  Hinkley 1997, §3.8): neither level alone gives the spread of a new run of the benchmark.
* **Moving blocks of queries** (circular block bootstrap, block length ``BLOCK`` = 10 queries):
  neighbouring queries are not independent (the sequence matcher's trajectory spans ds + 1 = 11
  of them; the views of neighbours overlap), and resampling single queries would understate the
  spread of recall at 100 % precision, which turns on runs of confident matches.
* **Percentile interval** of ``REPLICATES`` = 1000 replicates, 2.5 % and 97.5 %; the replicates
  come from a fixed seed, so an interval is deterministic for the same records.
* **Paired comparisons.** Two methods on the same task are compared on the same seed draws and
  the same query resamples (their records must hold the same seeds and queries); the difference
  is resolved when its interval excludes 0, otherwise the two are tied.

Everything is vectorised over the replicates (cumulative sums over the queries sorted by
confidence), so an interval costs milliseconds, not a re-evaluation per replicate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from safl_bench.errors import DataError
from safl_bench.metrics import AMBIGUOUS, CORRECT, Outcomes

#: Replicates of the bootstrap, and the seed of its random numbers (deterministic intervals).
REPLICATES = 1000
BOOTSTRAP_SEED = 20261202
#: Queries per block of the circular block bootstrap (see the module docstring).
BLOCK = 10
#: The central interval's coverage.
LEVEL = 0.95


def measure_names() -> tuple[str, ...]:
    """The measures `bootstrap` computes, named as in records (`safl_bench.records.Metrics`)."""
    return ("recall_at_100_precision", "recall_at_100_precision_of_correct", "f1_max",
            "f1_max_of_correct", "extended_precision", "extended_precision_of_correct", "auc",
            "recall_at_1", "recall_at_5", "recall_at_10")


def block_weights(n: int, replicates: int, rng: np.random.Generator, block: int = BLOCK) -> np.ndarray:
    """(replicates, n) int: how often each query is drawn by a circular block bootstrap
    (blocks of `block` consecutive queries, wrapping at the end, until n are drawn)."""
    if n <= 0:
        raise DataError("cannot resample an empty set of queries")
    block = max(1, min(block, n))
    n_blocks = -(-n // block)
    starts = rng.integers(0, n, (replicates, n_blocks))
    idx = (starts[:, :, None] + np.arange(block)[None, None, :]).reshape(replicates, -1)[:, :n] % n
    flat = idx + (np.arange(replicates) * n)[:, None]
    return np.bincount(flat.ravel(), minlength=replicates * n).reshape(replicates, n)


def weighted_measures(o: Outcomes, w: np.ndarray) -> dict[str, np.ndarray]:
    """Each measure of `measure_names` for every row of query weights `w` (R, N): the
    definitions of `safl_bench.metrics` with query i counted w[r, i] times. NaN where a measure
    is undefined for a replicate (no positive drawn; AUC with one class)."""
    scored = o.has_candidate
    conf, label = o.confidence[scored], o.label[scored]
    has_true = o.has_true_place[scored]
    w = np.asarray(w, dtype=np.float64)[:, scored]
    claimed = np.isfinite(conf)
    correct = claimed & (label == CORRECT)
    wrong = claimed & (label != CORRECT) & (label != AMBIGUOUS)
    pos = w @ has_true.astype(np.float64)
    n_correct = w @ correct.astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        out: dict[str, np.ndarray] = {"recall_at_1": n_correct / pos}

        # thresholds: the distinct confidences of the claimed queries, most confident first
        order = np.flatnonzero(claimed)[np.argsort(-conf[claimed], kind="stable")]
        c_sorted = conf[order]
        ends = np.r_[np.flatnonzero(np.diff(c_sorted) != 0), len(order) - 1] if len(order) else []
        tp = np.cumsum(w[:, order] * correct[order], axis=1)[:, ends]
        fp = np.cumsum(w[:, order] * wrong[order], axis=1)[:, ends]
        decided = tp + fp
        has = decided > 0  # a threshold of this replicate (some decided match drawn above it)
        r100 = np.where(has & (fp == 0), tp, 0).max(axis=1, initial=0)
        out["recall_at_100_precision"] = r100 / pos
        out["recall_at_100_precision_of_correct"] = np.where(n_correct > 0, r100 / n_correct, 0.0)
        f1 = np.where(has, 2 * tp / (decided + pos[:, None]), 0).max(axis=1, initial=0)
        f1c = np.where(has, 2 * tp / (decided + n_correct[:, None]), 0).max(axis=1, initial=0)
        out["f1_max"] = f1
        out["f1_max_of_correct"] = np.where(n_correct > 0, f1c, 0.0)
        first = np.argmax(has, axis=1) if has.shape[1] else np.zeros(len(w), np.int64)
        rows = np.arange(len(w))
        if has.shape[1]:  # precision at the most confident threshold drawn
            p_r0 = np.where(has.any(axis=1), tp[rows, first] / np.maximum(decided[rows, first], 1), 0.0)
        else:  # no match reported at all
            p_r0 = np.zeros(len(w))
        out["extended_precision"] = (p_r0 + out["recall_at_100_precision"]) / 2
        out["extended_precision_of_correct"] = (p_r0 + out["recall_at_100_precision_of_correct"]) / 2

        # ROC AUC: correct against wrong and unanswered (ranked lowest), ties counted half
        neg = wrong | ~claimed
        key = np.where(claimed, conf, -np.inf)
        asc = np.argsort(key, kind="stable")
        k_sorted = key[asc]
        start = np.r_[0, np.flatnonzero(np.diff(k_sorted) != 0) + 1]  # first of each group
        group = np.cumsum(np.r_[0, np.diff(k_sorted) != 0])  # group of each sorted query
        wn = np.cumsum(w[:, asc] * neg[asc], axis=1)
        before = np.where(start > 0, wn[:, np.maximum(start - 1, 0)], 0.0)  # (R, groups)
        ends_g = np.r_[start[1:] - 1, len(asc) - 1]
        within = wn[:, ends_g] - before
        wp = w[:, asc] * correct[asc]
        auc_num = (wp * (before[:, group] + 0.5 * within[:, group])).sum(axis=1)
        denom = wp.sum(axis=1) * wn[:, -1]
        out["auc"] = np.where(denom > 0, auc_num / np.where(denom > 0, denom, 1), np.nan)

        if o.true_rank is not None:
            rank = o.true_rank[scored]
            for n in (5, 10):
                out[f"recall_at_{n}"] = (w @ (has_true & (rank >= 1) & (rank <= n)).astype(float)) / pos
        bad = pos <= 0
        for name in out:
            if name != "auc":
                out[name] = np.where(bad, np.nan, out[name])
    return out


@dataclass(frozen=True)
class Interval:
    """A measure's mean over the seeds and its 95 % interval (`low`, `high`)."""

    mean: float
    low: float
    high: float
    n_seeds: int
    n_queries: int

    def excludes_zero(self) -> bool:
        return self.low > 0 or self.high < 0


def _draws(n_seeds: int, rng: np.random.Generator, replicates: int) -> np.ndarray:
    """(replicates, k): the seeds each replicate draws (k = n_seeds; just seed 0 when one)."""
    if n_seeds == 1:
        return np.zeros((replicates, 1), dtype=np.int64)
    return rng.integers(0, n_seeds, (replicates, n_seeds))


def _replicates(sides: Sequence[Sequence[Outcomes]], replicates: int) -> list[dict[str, np.ndarray]]:
    """Per side, every measure's (replicates,) values: the mean over the replicate's drawn
    seeds of the measure on that seed's resampled queries; all sides share the draws."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    n_seeds = len(sides[0])
    draws = _draws(n_seeds, rng, replicates)
    totals: list[dict[str, np.ndarray]] = [{} for _ in sides]
    for s in range(n_seeds):
        r_idx, _ = np.nonzero(draws == s)
        if not r_idx.size:
            continue
        w = block_weights(len(sides[0][s].confidence), r_idx.size, rng)
        for side, total in zip(sides, totals, strict=True):
            for name, values in weighted_measures(side[s], w).items():
                np.add.at(total.setdefault(name, np.zeros(replicates)), r_idx, values)
    return [{name: v / draws.shape[1] for name, v in total.items()} for total in totals]


def _points(seeds: Sequence[Outcomes]) -> dict[str, float]:
    """Every measure's mean over the seeds, on all their queries."""
    per = [weighted_measures(o, np.ones((1, len(o.confidence)))) for o in seeds]
    return {name: float(np.mean([p[name][0] for p in per])) for name in per[0]}


def _interval(point: float, values: np.ndarray, n_seeds: int, n_queries: int) -> Interval:
    finite = values[np.isfinite(values)]
    if not finite.size or not np.isfinite(point):
        return Interval(point, float("nan"), float("nan"), n_seeds, n_queries)
    lo, hi = np.quantile(finite, [(1 - LEVEL) / 2, (1 + LEVEL) / 2])
    return Interval(point, float(lo), float(hi), n_seeds, n_queries)


def bootstrap(seeds: Sequence[Outcomes], *, replicates: int = REPLICATES) -> dict[str, Interval]:
    """Every measure's mean over `seeds` (one `Outcomes` per noise seed of one cell) with its
    95 % interval over seeds and queries (module docstring)."""
    if not seeds:
        raise DataError("no seed to compute an interval from")
    points = _points(seeds)
    (values,) = _replicates([seeds], replicates)
    n = len(seeds[0].confidence)
    return {name: _interval(points[name], values[name], len(seeds), n) for name in points}


def paired_difference(a: Sequence[Outcomes], b: Sequence[Outcomes], *,
                      replicates: int = REPLICATES) -> dict[str, Interval]:
    """Every measure of A minus B on the same seeds and queries (`a[s]`, `b[s]`: seed s of
    each): the mean difference and its 95 % interval from the same resamples for both."""
    if len(a) != len(b) or not a:
        raise DataError(f"a paired comparison needs the same seeds on both sides, got {len(a)} "
                        f"and {len(b)}")
    for s, (x, y) in enumerate(zip(a, b, strict=True)):
        if len(x.confidence) != len(y.confidence) or not np.array_equal(x.has_true_place,
                                                                       y.has_true_place):
            raise DataError(f"seed #{s}: the two sides were not scored on the same queries")
    pa, pb = _points(a), _points(b)
    va, vb = _replicates([a, b], replicates)
    n = len(a[0].confidence)
    return {name: _interval(pa[name] - pb[name], va[name] - vb[name], len(a), n) for name in pa}
