"""Intervals of leaderboard cells and the ranks of a column, beyond the noise.

A cell is one (method, task, matching mode) over its seeds' records. Its interval is the 95 %
two-level bootstrap interval of `safl_bench.evaluation.uncertainty` (seeds and queries), computed once per
cell and matching mode (`cell_sample`, cached for the build: the recall, AUC and Recall@1
tables share it). Ranks:

* **Best beyond the noise** (bold): the best mean of a column (within one matching mode), and
  the paired difference to every other cell of the column excludes 0 (same task, so the same
  queries; compared on the seeds both cells have).
* **Tied for best** (marked "≈"): the best and every cell whose paired difference to it does
  not exclude 0; also when a difference cannot be computed (records without per-query
  outcomes, metrics version 1), since then nothing says the order is beyond the noise.
* A cell whose seeds are repeated runs of one cell (`records.is_repeat`: an unseedable method
  on a task where nothing is random) is paired run by run with the other cell's one run, so its
  run-to-run spread widens the difference's interval.

Which cells are ranked at all is the tables' rule (`safl_bench.leaderboard.tables`): not rows
seen in training, and not cells whose method answered fewer than half of the queries with a
true place (`tables.ANSWERED_MIN`).

With one seed the interval is over the queries alone (a fixed split, or a cell run once).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

from safl_bench.errors import DataError
from safl_bench.evaluation.uncertainty import Interval, Sample, sample
from safl_bench.results.records import ResultRecord, is_repeat, seed_outcomes

BEST, TIED = "best", "tied"

_ENABLED: ContextVar[bool] = ContextVar("leaderboard_intervals", default=True)
#: (id of each record, mode) -> (the records, kept so ids stay theirs; the sample or None)
_CACHE: dict[tuple[object, ...], tuple[tuple[ResultRecord, ...], Sample | None]] = {}
_CACHE_LIMIT = 8192


@contextmanager
def without_intervals() -> Iterator[None]:
    """Build tables without intervals or ranks (the site's per-record rebuilds need the values
    only; an interval per record would cost a bootstrap each)."""
    token = _ENABLED.set(False)
    try:
        yield
    finally:
        _ENABLED.reset(token)


def enabled() -> bool:
    return _ENABLED.get()


def cell_sample(records: Sequence[ResultRecord], mode: str) -> Sample | None:
    """The bootstrap of one cell (its seeds' records, in seed order) in matching `mode`; None
    when a record holds no per-query outcomes."""
    ordered = tuple(sorted(records, key=lambda r: r.seed))
    key = (mode, *(id(r) for r in ordered))
    hit = _CACHE.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], ordered, strict=True)):
        return hit[1]
    outcomes = seed_outcomes(ordered, mode)
    result = None if outcomes is None else sample(outcomes)
    if len(_CACHE) >= _CACHE_LIMIT:
        _CACHE.clear()
    _CACHE[key] = (ordered, result)
    return result


@dataclass(frozen=True)
class Ranked:
    """One cell of a column, as `rank` needs it."""

    index: int  # the caller's handle
    mean: float
    shown: float  # the mean as displayed (rounded): equal shown values are equal to a reader
    records: tuple[ResultRecord, ...]
    mode: str
    measure: str | None  # the `uncertainty` measure name; None: no interval (no ranks)


def _runs_paired(a: tuple[ResultRecord, ...], b: tuple[ResultRecord, ...]) -> tuple[ResultRecord, ...]:
    """`b`'s records paired with `a`'s: when `a` holds repeated runs of one cell
    (`records.is_repeat`) and `b` is one run of a cell without repeats, that run stands for
    every run of `a` (nothing in the task is random, so a method that can be seeded answers
    every seed alike), so the difference carries `a`'s run-to-run spread; else `b` as it is."""
    if len(b) == 1 and not is_repeat(b[0]) and any(is_repeat(r) for r in a):
        return tuple(dataclasses.replace(b[0], seed=r.seed) for r in a)
    return b


def _difference(a: Ranked, b: Ranked) -> Interval | None:
    """a - b on the seeds both have (a cell's repeated runs against another's one run: each
    run against that run, `_runs_paired`), or None when it cannot be computed."""
    if a.measure is None:
        return None
    ra, rb = _runs_paired(b.records, a.records), _runs_paired(a.records, b.records)
    shared = {r.seed for r in ra} & {r.seed for r in rb}
    if not shared:
        return None
    sa = cell_sample([r for r in ra if r.seed in shared], a.mode)
    sb = cell_sample([r for r in rb if r.seed in shared], b.mode)
    if sa is None or sb is None:
        return None
    try:
        return sa.minus(sb).get(a.measure)
    except DataError:  # not scored on the same queries: nothing to pair
        return None


def rank(cells: Sequence[Ranked], better: str) -> dict[int, str]:
    """{index: BEST or TIED} for the top of one column (module docstring); {} when fewer than
    two cells have values or all show the same value."""
    if len(cells) < 2 or len({c.shown for c in cells}) == 1:
        return {}
    sign = 1.0 if better == "higher" else -1.0
    ordered = sorted(cells, key=lambda c: (-sign * c.shown, c.index))
    top = ordered[0]
    tied = []
    for other in ordered[1:]:
        if other.shown == top.shown:
            tied.append(other)
            continue
        diff = _difference(top, other)
        resolved = diff is not None and diff.excludes_zero() and sign * diff.mean > 0
        if not resolved:
            tied.append(other)
    if not tied:
        return {top.index: BEST}
    return {c.index: TIED for c in (top, *tied)}
