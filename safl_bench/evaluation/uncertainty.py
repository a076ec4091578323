"""Uncertainty of a measure: a 95 % interval over the noise seeds AND the finite set of queries,
and paired differences between methods, from the per-query outcomes records hold.

Choices, and why:

* **Two-level (hierarchical) bootstrap.** One replicate draws the cell's seeds with
  replacement (the query noise: a new seed is a new draw of the noise), then, for each drawn
  seed, resamples that seed's queries; the replicate's value is the mean over its drawn seeds of
  the measure computed on the resampled queries, exactly as `safl_bench.evaluation.metrics` defines it
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

import numba
import numpy as np

from safl_bench.errors import DataError
from safl_bench.evaluation.metrics import AMBIGUOUS, AUTHORS_PRECISION, CORRECT, Outcomes

#: Replicates of the bootstrap, and the seed of its random numbers (deterministic intervals).
REPLICATES = 1000
BOOTSTRAP_SEED = 20261202
#: Queries per block of the circular block bootstrap (see the module docstring).
BLOCK = 10
#: The central interval's coverage.
LEVEL = 0.95


def measure_names() -> tuple[str, ...]:
    """The measures `bootstrap` computes, named as in records (`safl_bench.results.records.Metrics`)."""
    return ("recall_at_100_precision", "recall_at_100_precision_of_correct", "f1_max",
            "f1_max_of_correct", "extended_precision", "extended_precision_of_correct", "auc",
            "authors_recall_at_99p", "recall_at_1", "recall_at_5", "recall_at_10")


def block_weights(n: int, replicates: int, rng: np.random.Generator, block: int = BLOCK) -> np.ndarray:
    """(replicates, n) int: how often each query is drawn by a circular block bootstrap
    (blocks of `block` consecutive queries, wrapping at the end, until n are drawn)."""
    if n <= 0:
        raise DataError("cannot resample an empty set of queries")
    block = max(1, min(block, n))
    starts = rng.integers(0, n, (replicates, -(-n // block)))
    return _count_blocks(starts, n, block)


@numba.njit(cache=True)
def _count_blocks(starts: np.ndarray, n: int, block: int) -> np.ndarray:  # pragma: no cover - compiled
    """Counts of the queries that blocks starting at `starts` (R, B) draw, the first n per row."""
    out = np.zeros((starts.shape[0], n), dtype=np.int64)
    for r in range(starts.shape[0]):
        drawn = 0
        for b in range(starts.shape[1]):
            for k in range(block):
                if drawn == n:
                    break
                out[r, (starts[r, b] + k) % n] += 1
                drawn += 1
    return out


#: The measures the kernel writes, in its output's column order.
_KERNEL_MEASURES = ("recall_at_1", "recall_at_100_precision", "recall_at_100_precision_of_correct",
                    "f1_max", "f1_max_of_correct", "extended_precision",
                    "extended_precision_of_correct", "auc", "authors_recall_at_99p",
                    "recall_at_5", "recall_at_10")


@numba.njit(cache=True, error_model="numpy", inline="always")
def _row(w: np.ndarray, out: np.ndarray, has_true: np.ndarray, correct: np.ndarray,
         wrong: np.ndarray, desc: np.ndarray, desc_end: np.ndarray, asc: np.ndarray,
         asc_end: np.ndarray, neg: np.ndarray, hit5: np.ndarray,
         hit10: np.ndarray) -> None:  # pragma: no cover - compiled
    """`_KERNEL_MEASURES` of one replicate, query i counted w[i] times, into `out`. The masks
    are False for queries left out of every measure (no candidate). `desc`: the claimed queries,
    most confident first; `desc_end[g]`: whether position g ends a run of equal confidence (a
    threshold). `asc`: the scored queries by rising key (unanswered lowest), `asc_end` likewise;
    `neg`: wrong or unanswered; `hit5`, `hit10`: a true place among the first 5, 10."""
    pos = 0.0
    n_correct = 0.0
    n5 = 0.0
    n10 = 0.0
    for i in range(w.shape[0]):
        if has_true[i]:
            pos += w[i]
        if correct[i]:
            n_correct += w[i]
        if hit5[i]:
            n5 += w[i]
        if hit10[i]:
            n10 += w[i]
    tp = 0.0
    fp = 0.0
    r100 = 0.0
    f1 = 0.0
    f1c = 0.0
    a99 = 0.0  # TP at the least confident threshold with precision >= 0.99 (the authors' reading)
    p_r0 = 0.0
    seen = False
    for g in range(desc.shape[0]):
        i = desc[g]
        if correct[i]:
            tp += w[i]
        elif wrong[i]:
            fp += w[i]
        if not desc_end[g]:
            continue
        decided = tp + fp
        if decided <= 0:
            continue
        if not seen:  # precision at the most confident threshold drawn
            p_r0 = tp / decided
            seen = True
        if fp == 0 and tp > r100:
            r100 = tp
        if tp / decided >= AUTHORS_PRECISION and tp > a99:
            a99 = tp
        f1 = max(f1, 2 * tp / (decided + pos))
        f1c = max(f1c, 2 * tp / (decided + n_correct))
    # ROC AUC: correct against wrong and unanswered, ties counted half
    below = 0.0  # negatives' weight in the groups before this one
    auc_num = 0.0
    pos_w = 0.0
    g0 = 0
    for g in range(asc.shape[0]):
        if not asc_end[g]:
            continue
        within = 0.0
        pos_g = 0.0
        for h in range(g0, g + 1):
            i = asc[h]
            if neg[i]:
                within += w[i]
            elif correct[i]:
                pos_g += w[i]
        auc_num += pos_g * (below + 0.5 * within)
        pos_w += pos_g
        below += within
        g0 = g + 1
    denom = pos_w * below
    nan = np.nan
    r_at_100 = r100 / pos if pos > 0 else nan
    r_of_correct = r100 / n_correct if n_correct > 0 else 0.0
    out[0] = n_correct / pos if pos > 0 else nan
    out[1] = r_at_100
    out[2] = r_of_correct if pos > 0 else nan
    out[3] = f1 if pos > 0 else nan
    out[4] = (f1c if n_correct > 0 else 0.0) if pos > 0 else nan
    out[5] = (p_r0 + r_at_100) / 2
    out[6] = (p_r0 + r_of_correct) / 2 if pos > 0 else nan
    out[7] = auc_num / denom if denom > 0 else nan
    out[8] = (a99 / n_correct if n_correct > 0 else 0.0) if pos > 0 else nan
    out[9] = n5 / pos if pos > 0 else nan
    out[10] = n10 / pos if pos > 0 else nan


@numba.njit(cache=True, error_model="numpy")
def _weighted_kernel(w: np.ndarray, has_true: np.ndarray, correct: np.ndarray, wrong: np.ndarray,
                     desc: np.ndarray, desc_end: np.ndarray, asc: np.ndarray, asc_end: np.ndarray,
                     neg: np.ndarray, hit5: np.ndarray,
                     hit10: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """(R, 11): `_row` for every row of weights `w` (R, N)."""
    out = np.empty((w.shape[0], len(_KERNEL_MEASURES)))
    for r in range(w.shape[0]):
        _row(w[r], out[r], has_true, correct, wrong, desc, desc_end, asc, asc_end, neg, hit5, hit10)
    return out


@numba.njit(cache=True, error_model="numpy", parallel=True)
def _block_kernel(starts: np.ndarray, block: int, has_true: np.ndarray, correct: np.ndarray,
                  wrong: np.ndarray, desc: np.ndarray, desc_end: np.ndarray, asc: np.ndarray,
                  asc_end: np.ndarray, neg: np.ndarray, hit5: np.ndarray,
                  hit10: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """(R, 11): `_row` for the circular block resamples whose blocks start at `starts` (R, B):
    the weights `block_weights` would give, counted one replicate at a time (no (R, N) matrix),
    replicates in parallel."""
    n = has_true.shape[0]
    out = np.empty((starts.shape[0], len(_KERNEL_MEASURES)))
    for r in numba.prange(starts.shape[0]):
        w = np.zeros(n)
        drawn = 0
        for b in range(starts.shape[1]):
            j = starts[r, b]
            for _ in range(block):
                if drawn == n:
                    break
                w[j] += 1.0
                drawn += 1
                j += 1
                if j == n:
                    j = 0
        _row(w, out[r], has_true, correct, wrong, desc, desc_end, asc, asc_end, neg, hit5, hit10)
    return out


def _run_ends(sorted_keys: np.ndarray) -> np.ndarray:
    """Whether each position of sorted keys is the last of its run of equal keys."""
    return np.r_[sorted_keys[1:] != sorted_keys[:-1], True] if len(sorted_keys) else np.zeros(0, bool)


def _kernel_inputs(o: Outcomes) -> tuple[np.ndarray, ...]:
    """The masks and orders `_row` reads, over all of `o`'s queries (those without a candidate
    are in no mask and no order: left out of every measure, as in `safl_bench.evaluation.metrics`)."""
    scored = o.has_candidate
    claimed = scored & np.isfinite(o.confidence)
    correct = claimed & (o.label == CORRECT)
    wrong = claimed & (o.label != CORRECT) & (o.label != AMBIGUOUS)
    has_true = scored & o.has_true_place
    # thresholds: the distinct confidences of the claimed queries, most confident first
    mine = np.flatnonzero(claimed)
    desc = mine[np.argsort(-o.confidence[mine], kind="stable")]
    key = np.where(claimed, o.confidence, -np.inf)
    kept = np.flatnonzero(scored)
    asc = kept[np.argsort(key[kept], kind="stable")]
    if o.true_rank is not None:
        hit5 = has_true & (o.true_rank >= 1) & (o.true_rank <= 5)
        hit10 = has_true & (o.true_rank >= 1) & (o.true_rank <= 10)
    else:
        hit5 = hit10 = np.zeros(len(scored), bool)
    return (has_true, correct, wrong, desc, _run_ends(o.confidence[desc]), asc,
            _run_ends(key[asc]), scored & (wrong | ~claimed), hit5, hit10)


def _named(o: Outcomes, values: np.ndarray) -> dict[str, np.ndarray]:
    names = _KERNEL_MEASURES if o.true_rank is not None else _KERNEL_MEASURES[:-2]
    return {name: values[:, j] for j, name in enumerate(names)}


def weighted_measures(o: Outcomes, w: np.ndarray) -> dict[str, np.ndarray]:
    """Each measure of `measure_names` for every row of query weights `w` (R, N): the
    definitions of `safl_bench.evaluation.metrics` with query i counted w[r, i] times. NaN where a measure
    is undefined for a replicate (no positive drawn; AUC with one class); Recall@5 and @10 only
    where the outcomes hold ranks. Compiled (`_row`, one pass over the queries per replicate)."""
    w = np.ascontiguousarray(w, dtype=np.float64)
    return _named(o, _weighted_kernel(w, *_kernel_inputs(o)))


def block_measures(o: Outcomes, replicates: int, rng: np.random.Generator,
                   block: int = BLOCK) -> dict[str, np.ndarray]:
    """`weighted_measures` of `replicates` circular block resamples of `o`'s queries: the same
    values as ``weighted_measures(o, block_weights(n, replicates, rng, block))`` (the same
    draws of `rng`), without the (replicates, n) weight matrix."""
    n = len(o.confidence)
    if n <= 0:
        raise DataError("cannot resample an empty set of queries")
    block = max(1, min(block, n))
    starts = rng.integers(0, n, (replicates, -(-n // block)))
    return _named(o, _block_kernel(starts, block, *_kernel_inputs(o)))


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

    def format(self, scale: float = 1.0, decimals: int = 1) -> str:
        """'mean [low, high]' (values times `scale`); 'mean [n/a]' when the interval is
        undefined (a measure NaN in every replicate), 'n/a' when the mean is too."""
        def number(value: float) -> str:
            text = f"{value * scale:.{decimals}f}"
            return text.lstrip("-") if float(text) == 0 else text  # no "-0.0"

        if self.mean != self.mean:
            return "n/a"
        if self.low != self.low:
            return f"{number(self.mean)} [n/a]"
        return f"{number(self.mean)} [{number(self.low)}, {number(self.high)}]"


def _draws(n_seeds: int, rng: np.random.Generator, replicates: int) -> np.ndarray:
    """(replicates, k): the seeds each replicate draws (k = n_seeds; just seed 0 when one)."""
    if n_seeds == 1:
        return np.zeros((replicates, 1), dtype=np.int64)
    return rng.integers(0, n_seeds, (replicates, n_seeds))


def _replicates(seeds: Sequence[Outcomes], replicates: int) -> dict[str, np.ndarray]:
    """Every measure's (replicates,) values: the mean over the replicate's drawn seeds of the
    measure on that seed's resampled queries. The draws depend only on the number of seeds and
    of queries (a fixed generator), so two cells of the same task get the same resamples: their
    replicates subtract into a paired difference."""
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    n_seeds = len(seeds)
    draws = _draws(n_seeds, rng, replicates)
    total: dict[str, np.ndarray] = {}
    for s in range(n_seeds):
        r_idx, _ = np.nonzero(draws == s)
        if not r_idx.size:
            continue
        for name, values in block_measures(seeds[s], r_idx.size, rng).items():
            np.add.at(total.setdefault(name, np.zeros(replicates)), r_idx, values)
    return {name: v / draws.shape[1] for name, v in total.items()}


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


@dataclass(frozen=True)
class Sample:
    """One cell's bootstrap: every measure's point value (mean over the seeds, all queries) and
    its replicates. Kept so that intervals and paired differences of many cells cost one
    bootstrap per cell (`minus` subtracts the replicates of two cells of one task)."""

    points: dict[str, float]
    values: dict[str, np.ndarray]
    truth: tuple[tuple[int, bytes], ...]  # per seed: (queries, which have a true place): pairing

    @property
    def n_seeds(self) -> int:
        return len(self.truth)

    @property
    def n_queries(self) -> int:
        return self.truth[0][0]

    def intervals(self) -> dict[str, Interval]:
        """Every measure's mean and 95 % interval."""
        return {name: _interval(self.points[name], self.values[name], self.n_seeds, self.n_queries)
                for name in self.points}

    def minus(self, other: Sample) -> dict[str, Interval]:
        """Every measure of this cell minus `other`'s (same seeds and queries): the mean
        difference and its 95 % interval from the same resamples for both."""
        if self.n_seeds != other.n_seeds:
            raise DataError(f"a paired comparison needs the same seeds on both sides, got "
                            f"{self.n_seeds} and {other.n_seeds}")
        for s, (x, y) in enumerate(zip(self.truth, other.truth, strict=True)):
            if x != y:
                raise DataError(f"seed #{s}: the two sides were not scored on the same queries")
        return {name: _interval(self.points[name] - other.points[name],
                                self.values[name] - other.values[name], self.n_seeds, self.n_queries)
                for name in self.points if name in other.points}


def sample(seeds: Sequence[Outcomes], *, replicates: int = REPLICATES) -> Sample:
    """The bootstrap of one cell (`seeds`: one `Outcomes` per noise seed), module docstring."""
    if not seeds:
        raise DataError("no seed to compute an interval from")
    return Sample(_points(seeds), _replicates(seeds, replicates),
                  tuple((len(o.confidence), np.packbits(o.has_true_place).tobytes()) for o in seeds))


def bootstrap(seeds: Sequence[Outcomes], *, replicates: int = REPLICATES) -> dict[str, Interval]:
    """Every measure's mean over `seeds` (one `Outcomes` per noise seed of one cell) with its
    95 % interval over seeds and queries (module docstring)."""
    return sample(seeds, replicates=replicates).intervals()


def paired_difference(a: Sequence[Outcomes], b: Sequence[Outcomes], *,
                      replicates: int = REPLICATES) -> dict[str, Interval]:
    """Every measure of A minus B on the same seeds and queries (`a[s]`, `b[s]`: seed s of
    each): the mean difference and its 95 % interval from the same resamples for both."""
    if len(a) != len(b) or not a:
        raise DataError(f"a paired comparison needs the same seeds on both sides, got {len(a)} "
                        f"and {len(b)}")
    return sample(a, replicates=replicates).minus(sample(b, replicates=replicates))
