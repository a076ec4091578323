"""Exact matching in bounded memory: the shared matcher on the difference matrix one block of
query rows at a time, never holding the whole (Nq, Ndb) matrix.

Why it is exact. Every step of the matcher (`safl_bench.matching.matcher`, module doc) reads
one query row at a time, or a few neighbouring ones:

1. Contrast enhancement (Eq. 5) runs along the database axis of ONE row: row i of the enhanced
   matrix is a function of row i of D alone, computed by the same kernel on the same values.
2. The sequence search of query T reads the enhanced rows its trajectories visit, T + u for
   u = u_lo .. u_hi (`MatcherConfig.u_range`), and `db_limit[T]`; nothing else. A block of
   queries is searched with those rows in memory: the block's own rows, the ``-u_lo`` rows
   before it (kept from the previous block, not recomputed) and the ``u_hi`` rows after it (the
   last queries of a block wait for the next block when the trajectory looks ahead).
3. The shift (``shift=True``) is the minimum of the whole enhanced matrix: the minimum of the
   blocks' minima, the same number. It is applied after the last block, as the dense path
   applies it after the search.

So a query's match, score and velocity are the same floating-point numbers as on the whole
matrix (the dense path, `matcher.match`, is the single-block case of the same code: the search
kernel takes the block's position), provided the rows themselves are: the difference of a
block of queries must equal those rows of the whole difference. That holds for a distance that
treats each query on its own (`Method.rowwise_distance`), computed with the same arithmetic:
`safl_bench.methods.distance.sqeuclidean` works in query chunks of 1024 rows, so blocks are
whole multiples of 1024 rows (`block_rows`), and every chunk is the same BLAS call on the same
numbers as in one call over all queries. A method whose distance is not row-wise gets the
whole matrix (`safl_bench.evaluation.cell` says so in one line).

Memory. Per block: the block's difference rows, each matcher setting's enhanced rows plus the
trajectory's rows before and after the block, in the matcher's dtype (a setting without
enhancement and without trajectory, single-frame matching, reads the difference rows as they are).
The default budget, 2 GB, keeps blocks of whole multiples of 1024 rows up to databases of
about 170 000 frames. Beyond that, or under a smaller budget, a block holds fewer than 1024
rows, and BLAS may round the last bit of a distance differently for a smaller product than
for the 1024-row one; matches are still the same for the same budget, run after run. `block_rows` sizes the
block so that this stays under a budget (`DEFAULT_BLOCK_MB`, or ``SAFL_BLOCK_MB``, or the
``--block-mb`` option of ``safl-bench run``): peak memory grows with Ndb (one row), not with
Nq x Ndb. The budget changes no result: it is not a matcher setting and records do not carry it.

Spread over workers. The queries can also be cut into spans of whole blocks (`spans`), each
searched on its own (`search_span`, on a worker) and joined (`combine`). A span computes the
blocks that hold its rows and the rows its trajectories reach before and after it, whole, as
the serial pass computes them (so the same numbers; a neighbour's block is computed twice,
which costs one block of distances per span), keeps only the rows it reads, and reports the
minimum of its own rows. Each query is searched by exactly one span on the same rows, and the
shift is the minimum of the spans' minima, so the joined result is the serial one bit for bit
(`match_rows` is the one-span case). Each worker holds one span's rows: the budget is per
worker.
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from safl_bench.errors import ConfigError, DataError
from safl_bench.matching.matcher import (
    _DTYPES,
    MatcherConfig,
    MatchResult,
    _as_difference,
    _enhance_kernel,
    db_limits,
    finish,
    search,
    window_of,
)

#: The memory budget (MB) of one block's rows when none is given and ``SAFL_BLOCK_MB`` is unset.
DEFAULT_BLOCK_MB = 2048
#: The environment variable that sets the budget for every run of this process and its workers.
BLOCK_MB_ENV = "SAFL_BLOCK_MB"
#: Blocks are whole multiples of this many rows (the query chunk of `methods.distance`), when
#: the budget allows one: then a block's distances are the same BLAS calls as the whole matrix's.
ALIGN_ROWS = 1024


def block_mb(value: float | str | None = None, what: str = "block size") -> float:
    """The budget in MB: `value` (`what` names it in errors), else ``SAFL_BLOCK_MB``, else
    `DEFAULT_BLOCK_MB`; a ConfigError naming the value when it is not a number > 0."""
    source = what
    if value is None:
        value = os.environ.get(BLOCK_MB_ENV)
        source = BLOCK_MB_ENV
        if value is None or value == "":
            return float(DEFAULT_BLOCK_MB)
    try:
        mb = float(value)
    except (TypeError, ValueError):
        mb = float("nan")
    if not np.isfinite(mb) or mb <= 0:
        raise ConfigError(f"{source} must be a number of MB > 0, got {value!r}")
    return mb


def block_rows(n_queries: int, n_database: int, budget_mb: float | None = None, *,
               itemsize: int = 4, copies: int = 3) -> int:
    """Query rows per block: as many as fit `copies` arrays of (rows, Ndb) items in the budget
    (the difference rows, and an enhanced copy with its trajectory rows for each of the two
    matching modes), rounded down to a multiple of `ALIGN_ROWS` when at least that many fit,
    at least 1, at most all queries."""
    mb = block_mb(budget_mb)
    per_row = max(n_database, 1) * itemsize * copies
    rows = int(mb * 1e6 // per_row)
    if rows >= ALIGN_ROWS:
        rows -= rows % ALIGN_ROWS
    return int(min(max(rows, 1), max(n_queries, 1)))


@dataclass
class _Stream:
    """One matcher setting's state across blocks: its enhanced rows [lo, lo + len(rows)), the
    next query to search, the running minimum, the outputs, the seconds spent."""

    cfg: MatcherConfig
    window: int
    rows: np.ndarray
    lo: int = 0
    next_query: int = 0
    minimum: float = np.inf
    seconds: float = 0.0


@dataclass
class SpanResult:
    """What searching the queries of one span `[first, stop)` gave, per matcher setting: the
    search's outputs (before the shift), the minimum of the span's enhanced rows (the shift is
    the minimum over all spans) and the seconds spent enhancing and searching. Plain arrays and
    numbers, so a worker can send it back (`match_spread`)."""

    first: int
    stop: int
    found: list[tuple[np.ndarray, ...]]
    minima: list[float]
    seconds: list[float]


def match_rows(rows: Callable[[int, int], np.ndarray], n_queries: int, n_database: int,
               configs: Sequence[MatcherConfig], *, db_limit: np.ndarray | None = None,
               windows: Sequence[int | None] | None = None, block: int | None = None,
               visit: Callable[[int, np.ndarray], None] | None = None,
               ) -> tuple[list[MatchResult], list[float]]:
    """Match every setting of `configs` on the difference matrix whose rows ``[a, b)``
    ``rows(a, b)`` returns, one block of `block` rows at a time (module doc; `block_rows` when
    None). `windows`: each setting's ``enhance_window`` argument (`matcher.window_of`).
    `visit(a, D_rows)` sees every block of raw rows once (for measures read from them, as the
    true places' ranks). Returns the results (bit for bit `matcher.match`'s on the whole matrix)
    and, per setting, the seconds spent enhancing and searching (not computing the rows)."""
    nq, ndb = _shape(n_queries, n_database)
    step = _step(nq, ndb, block)
    span = search_span(rows, nq, ndb, configs, (0, nq), db_limit=db_limit, windows=windows,
                       block=step, visit=visit)
    return combine(configs, [span], nq, ndb, windows=windows)


def _shape(n_queries: int, n_database: int) -> tuple[int, int]:
    nq, ndb = int(n_queries), int(n_database)
    if nq < 1 or ndb < 1:
        raise DataError(f"difference matrix is empty (shape ({nq}, {ndb}))")
    return nq, ndb


def _step(nq: int, ndb: int, block: int | None, copies: int = 3) -> int:
    step = block_rows(nq, ndb, copies=copies) if block is None else block
    if not isinstance(step, int | np.integer) or isinstance(step, bool) or step < 1:
        raise ConfigError(f"block size must be a whole number of query rows >= 1, got {block!r}")
    return int(step)


def _windows(configs: Sequence[MatcherConfig], windows: Sequence[int | None] | None) -> list[int]:
    given = list(windows) if windows is not None else [None] * len(configs)
    if len(given) != len(configs):
        raise ConfigError(f"{len(configs)} matcher settings but {len(given)} windows")
    return [window_of(c, w) for c, w in zip(configs, given, strict=True)]


def spans(n_queries: int, block: int, parts: int) -> list[tuple[int, int]]:
    """`[0, n_queries)` cut into at most `parts` contiguous spans of whole blocks of `block`
    rows (the last block may be shorter), as even as whole blocks allow: the spans that
    `match_spread` searches apart. Cut on block boundaries so that each span computes the very
    blocks the serial pass computes."""
    n_blocks = -(-int(n_queries) // int(block))
    k = max(1, min(int(parts), n_blocks))
    edges = [round(i * n_blocks / k) * int(block) for i in range(k + 1)]
    edges[-1] = int(n_queries)
    return [(a, b) for a, b in itertools.pairwise(edges) if b > a]


def search_span(rows: Callable[[int, int], np.ndarray], n_queries: int, n_database: int,
                configs: Sequence[MatcherConfig], span: tuple[int, int], *,
                db_limit: np.ndarray | None = None, windows: Sequence[int | None] | None = None,
                block: int | None = None, visit: Callable[[int, np.ndarray], None] | None = None,
                ) -> SpanResult:
    """Search the queries of `span` ``[first, stop)`` of the whole matrix: the blocks of `block`
    rows (counted from row 0, as the serial pass cuts them) that hold the span's rows and the
    rows its trajectories reach before and after it, each block computed whole by `rows` (so
    its numbers are the serial pass's), its rows outside that reach dropped before enhancing.
    `visit` sees the span's own raw rows. `first` must start a block (`spans` cuts so)."""
    nq, ndb = _shape(n_queries, n_database)
    step = _step(nq, ndb, block)
    first, stop = int(span[0]), int(span[1])
    if not (0 <= first < stop <= nq) or first % step:
        raise ConfigError(f"query span [{first}, {stop}) is not whole blocks of {step} rows "
                          f"within the {nq} queries")
    limit = db_limits(db_limit, nq, ndb)
    # the rows each setting's queries of the span read: [first + u_lo, stop + u_hi)
    reach = [(max(0, first + u_lo), min(nq, stop + u_hi)) for u_lo, u_hi in
             (c.u_range() for c in configs)]
    lo, hi = min(r[0] for r in reach), max(r[1] for r in reach)
    streams = [_Stream(c, w, np.empty((0, ndb), _DTYPES[c.dtype]), lo=r[0], next_query=first)
               for c, w, r in zip(configs, _windows(configs, windows), reach, strict=True)]
    found: list[list[tuple[np.ndarray, ...]]] = [[] for _ in streams]
    for a in range(lo - lo % step, hi, step):
        b = min(a + step, nq)
        raw = np.asarray(rows(a, b))
        if raw.shape != (b - a, ndb):
            raise DataError(f"rows {a}..{b - 1} of the difference matrix have shape {raw.shape}, "
                            f"expected ({b - a}, {ndb})")
        own = raw[max(a, first) - a:min(b, stop) - a]
        if visit is not None and len(own):
            visit(max(a, first), own)
        for s, out, (r_lo, r_hi) in zip(streams, found, reach, strict=True):
            r0, r1 = max(a, r_lo), min(b, r_hi)  # the block's rows this setting reads
            if r1 <= r0:
                continue
            t0 = time.perf_counter()
            try:
                arr = _as_difference(raw[r0 - a:r1 - a], _DTYPES[s.cfg.dtype])
            except DataError as exc:
                raise DataError(f"rows {a}..{b - 1}: {exc}") from None
            out.append(_advance(s, arr, r0, r1, nq, limit, (first, stop)))
            s.seconds += time.perf_counter() - t0
    return SpanResult(first, stop, [_joined(out) for out in found],
                      [s.minimum for s in streams], [s.seconds for s in streams])


def _joined(parts: list[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    empty = (np.empty(0, np.int64), np.empty(0), np.empty(0), np.empty(0, np.int64),
             np.empty(0, np.int64))
    return tuple(np.concatenate([p[k] for p in parts]) if parts else empty[k] for k in range(5))


def combine(configs: Sequence[MatcherConfig], parts: Sequence[SpanResult], n_queries: int,
            n_database: int, *, windows: Sequence[int | None] | None = None,
            ) -> tuple[list[MatchResult], list[float]]:
    """The results of the spans `parts`, which must cover the `n_queries` queries once, in any
    order: each setting's outputs in query order, shifted by the minimum over all spans (module
    doc, 3), and its seconds summed."""
    ordered = sorted(parts, key=lambda p: p.first)
    at = 0
    for p in ordered:
        if p.first != at:
            break
        at = p.stop
    if at != n_queries or len({p.first for p in ordered}) < len(ordered):
        raise DataError(f"the query spans leave a gap or overlap at query {at} of {n_queries}")
    results, seconds = [], []
    for k, (cfg, window) in enumerate(zip(configs, _windows(configs, windows), strict=True)):
        cols = _joined([p.found[k] for p in ordered])
        shift = float(min(p.minima[k] for p in ordered)) if cfg.shift else 0.0
        results.append(finish(cfg, (cols[0], cols[1], cols[2], cols[3], cols[4]), shift,
                              int(n_database), window))
        seconds.append(float(sum(p.seconds[k] for p in ordered)))
    return results, seconds


def _advance(s: _Stream, arr: np.ndarray, a: int, b: int, nq: int,
             limit: np.ndarray, span: tuple[int, int]) -> tuple[np.ndarray, ...]:
    """Add rows [a, b) to `s`, search every query of `span` whose rows are now all there, drop
    the rows no later query reads; the search's outputs for those queries. The minimum counts
    the span's own rows only (each row of the matrix belongs to one span)."""
    first, stop = span
    u_lo, u_hi = s.cfg.u_range()
    keep = s.rows
    w = s.window
    if w == 0 and not len(keep):  # nothing to add to: read the rows as they are
        held = arr
    else:
        held = np.empty((len(keep) + (b - a), arr.shape[1]), dtype=arr.dtype)
        held[:len(keep)] = keep
        if w > 0:
            before, after = (w // 2, w // 2) if s.cfg.enhance_mode == "centred" else (w, 0)
            _enhance_kernel(arr, held[len(keep):], before, after)
        else:
            held[len(keep):] = arr
    if s.cfg.shift and min(b, stop) > max(a, first):
        new = held[len(keep):]
        s.minimum = min(s.minimum, float(new[max(a, first) - a:min(b, stop) - a].min()))
    end = stop if b >= min(nq, stop + u_hi) else min(stop, max(s.next_query, b - u_hi))
    q0, nqb = s.next_query, end - s.next_query
    result = search(held, s.cfg, limit, q0, nqb, s.lo, nq) if nqb > 0 else (
        np.empty(0, np.int64), np.empty(0), np.empty(0), np.empty(0, np.int64),
        np.empty(0, np.int64))
    s.next_query = max(s.next_query, end)
    first_read = max(0, s.next_query + u_lo)  # the first row a query not yet searched reads
    s.rows = held[first_read - s.lo:].copy() if first_read > s.lo else held
    s.lo = max(s.lo, first_read)
    return result
