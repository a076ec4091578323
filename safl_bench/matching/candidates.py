"""Candidate search: the sequence matcher through each query's k nearest database frames only,
in the spirit of Fast-SeqSLAM (Siam and Zhang, ICRA 2017), which searches sequences through
each query's approximate nearest neighbours instead of the whole difference matrix.

Opt-in (the evaluation settings ``candidates=K`` and ``index=flat|ivf``; records carry both, so
tables never mix its cells with the exact matcher's: their preset label differs). The exact
matcher (`safl_bench.matching.matcher`, in blocks: `safl_bench.matching.blocks`) stays the
definition; this mode approximates it, and `docs/reference/speed.md` gives its measured
accuracy cost. What it does, with the choices Fast-SeqSLAM's idea leaves open:

1. Candidates: each query row's `k` nearest database frames by the cell's difference. With
   the ``flat`` index (exact search) they are the `k` lowest values of the query's own row of
   the exact matcher's difference matrix (ties: the lower frame), read as the rows are made,
   one block at a time (`search_rows`). The rows are the BLAS products the exact matcher makes
   (`safl_bench.methods.distance`), so no second index is built: FAISS's flat index made the
   same N x N x D product, and at KITTI 00's size that product alone is most of the time
   (module doc of `safl_bench.bench.matching_bench`). With the ``ivf`` index (approximate):
   FAISS's ``IndexIVFFlat`` over the database descriptors by L2, `ivf_lists` lists,
   `IVF_PROBE` of them searched, k-means with FAISS's fixed seed, so the same candidates every
   run. With a ``db_limit`` (the revisit protocol), only frames ``j < db_limit[T]`` are
   candidates of T: the flat search reads only them; FAISS searches queries in groups of
   `GROUP` with a range selector up to the group's largest limit and ``k`` plus the spread of
   the group's limits neighbours, so that after dropping each query's forbidden frames it
   still holds its k nearest allowed ones.
2. The reported frame of query T is one of T's own candidates: ``S(T, j, V)`` (module doc of
   the matcher, 2-5: the same trajectories, velocities, edge and out-of-range rules) is
   evaluated for ``j`` in T's candidates only, and the match is the lowest (ties: lowest
   velocity, then lowest j, the one tie rule). This is where the accuracy is lost: a true
   match whose single frame is not among the k nearest cannot be reported, however well its
   sequence agrees.
3. The values the trajectories read are exact, and the contrast enhancement (Eq. 5) of a point
   uses the differences of its whole window. With the ``flat`` index they are read from the
   rows held (the block's, and the rows the trajectories reach before and after it), so with
   ``k`` = the whole database this mode finds the exact matcher's matches; its enhancement
   sums in float64 in its own order, so scores agree up to rounding. With ``ivf``, which holds
   no rows, each point's difference is made from the descriptors (Eq. 4's squared L2, or its
   root for ``distance=euclidean``): each dot product is summed in float32 by the kernel's
   own tile, the rest in float64. That work is arranged for the cache: a query's candidates
   one by one, each candidate's trajectory points four at a time, whose dot products with the
   union of the frames their windows read are made 4 x 4 at once (`_tile`; each row and frame
   read serves four products, against one when each product is made alone, which was 1.6x
   slower at KITTI 00 size). Each (candidate, velocity) sum adds its points in ascending order.
4. What it cannot see of the whole matrix, it takes from what it computed: the shift that
   makes S non-negative (``shift=True``) is the lowest enhanced value it read (the ranking by
   the paper's ``min`` score does not depend on it), a window's zero-spread floor is 1e-12 of
   the spread of the differences computed for that point's row and candidate, and the ratio
   score's second-best S is the best over the other candidates outside the ratio window (1.0,
   no evidence, when there is none).
5. The single-frame answer is the nearest candidate; a query's true place that is not among
   its candidates is ranked at no N (`safl_bench.methods.retrieval.NOT_RETRIEVED`), as for a
   retrieval method that did not return it.

Only descriptors compared by L2 can be searched so (the ``ivf`` index is an L2 index; the flat
search keeps the same rule, so that the two indexes rank by the same difference): a method with
its own distance (`Method.distance` overridden: SAD's L1, Scan Context's shifted cosine) is a
ConfigError unless the cell's ``distance=euclidean`` says to compare its descriptors by L2.

Memory. The flat path holds one block of rows and the rows its trajectories reach before and
after it (two copies of a block in the budget of `safl_bench.matching.blocks.block_rows`), and
the (Nq, k) candidates; FAISS is needed for the ``ivf`` index only.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from safl_bench.errors import ConfigError, DataError
from safl_bench.matching import blocks
from safl_bench.matching.matcher import (
    MatcherConfig,
    MatchResult,
    _as_difference,
    db_limits,
    finish,
    window_of,
)
from safl_bench.matching.settings import INDEXES

#: Inverted lists searched per query by the ``ivf`` index.
IVF_PROBE = 16
#: Queries searched together under one range selector (module doc, 1).
GROUP = 64
#: The extra that installs FAISS.
EXTRA = "pip install 'safl-bench[faiss]' (or pip install faiss-cpu)"


def ivf_lists(n_database: int) -> int:
    """The ``ivf`` index's lists: about 4 sqrt(Ndb) (FAISS's guideline is 4-16 sqrt(N)), with at
    least 39 training points per list (k-means' own minimum), at least 1."""
    return int(max(1, min(round(4 * np.sqrt(n_database)), n_database // 39)))


def faiss_module() -> Any:
    """FAISS, or a ConfigError naming the extra that installs it."""
    try:
        import faiss
    except ImportError:
        raise ConfigError(f"candidate search needs FAISS, which is not installed: {EXTRA}") from None
    return faiss


@dataclass(frozen=True)
class Candidates:
    """Each query's candidate database frames, ascending (-1 pads a row with fewer), and the
    difference the index ranked them by (+inf on padding): the difference row's value for the
    flat search, FAISS's squared L2 for ``ivf``."""

    index: np.ndarray  # (Nq, k) int64
    distance: np.ndarray  # (Nq, k) float64


def check_k(k: Any, n_database: int) -> int:
    """`k` as an int in [1, Ndb], or a ConfigError naming it."""
    if not isinstance(k, int | np.integer) or isinstance(k, bool) or k < 1:
        raise ConfigError(f"candidates must be a whole number of frames >= 1, got {k!r}")
    if k > n_database:
        raise ConfigError(f"candidates={k} is more than the database's {n_database} frames; "
                          f"give at most {n_database}")
    return int(k)


def nearest(queries: np.ndarray, database: np.ndarray, k: int, *, index: str = "flat",
            db_limit: np.ndarray | None = None, block: int | None = None) -> Candidates:
    """The `k` nearest database frames of each query by L2 (module doc, 1); ``flat``: by the
    squared L2 rows of `safl_bench.methods.distance.sqeuclidean`, `block` query rows at a time
    (`safl_bench.matching.blocks.block_rows` when None)."""
    if index not in INDEXES:
        raise ConfigError(f"index must be one of {', '.join(map(repr, INDEXES))}, got {index!r}")
    q, db = _descriptors(queries, database)
    nq, ndb = len(q), len(db)
    k = check_k(k, ndb)
    limit = db_limits(db_limit, nq, ndb)
    if index == "flat":
        from safl_bench.methods.distance import sqeuclidean

        return search_rows(lambda a, b: sqeuclidean(q[a:b], db), nq, ndb, k, [],
                           db_limit=limit, block=block)[0]
    faiss = faiss_module()
    centre = db.mean(axis=0, dtype=np.float64)
    dbc = np.ascontiguousarray(db - centre, dtype=np.float32)
    qc = np.ascontiguousarray(q - centre, dtype=np.float32)
    dim = db.shape[1]
    lists = ivf_lists(ndb)
    ix = faiss.IndexIVFFlat(faiss.IndexFlatL2(dim), dim, lists)
    ix.train(dbc)
    probe = {"nprobe": min(IVF_PROBE, lists)}
    ix.add(dbc)
    out_i = np.full((nq, k), -1, np.int64)
    out_d = np.full((nq, k), np.inf)
    if db_limit is None:
        dist, idx = ix.search(qc, k, params=faiss.SearchParametersIVF(**probe))
        out_i[:], out_d[:] = idx, dist
    else:
        order = np.argsort(limit, kind="stable")
        for g in range(0, nq, GROUP):
            rows = order[g:g + GROUP]
            top, bottom = int(limit[rows].max()), int(limit[rows].min())
            if top <= 0:
                continue
            want = min(top, k + top - bottom)
            sel = faiss.IDSelectorRange(0, top)
            params = faiss.SearchParametersIVF(sel=sel, **probe)
            dist, idx = ix.search(qc[rows], want, params=params)
            for r, d_row, i_row in zip(rows, dist, idx, strict=True):
                keep = (i_row >= 0) & (i_row < limit[r])
                i_k, d_k = i_row[keep][:k], d_row[keep][:k]
                out_i[r, :len(i_k)], out_d[r, :len(d_k)] = i_k, d_k
    # ascending frames: the tie rule's "lowest j" is the first in the row
    key = np.where(out_i >= 0, out_i, np.iinfo(np.int64).max)
    o = np.argsort(key, axis=1, kind="stable")
    return Candidates(np.take_along_axis(out_i, o, 1),
                      np.take_along_axis(out_d.astype(np.float64), o, 1))


def _descriptors(queries: np.ndarray, database: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    from safl_bench.methods.distance import _as_descriptors

    q = _as_descriptors(queries, "query")
    db = _as_descriptors(database, "database")
    if q.shape[1] != db.shape[1]:
        raise DataError(f"query and database descriptors differ in length: {q.shape[1]} vs "
                        f"{db.shape[1]}")
    return q, db


def match_candidates(queries: np.ndarray, database: np.ndarray, cand: Candidates,
                     config: MatcherConfig, *, db_limit: np.ndarray | None = None,
                     enhance_window: int | None = None, root: bool = False) -> MatchResult:
    """`config`'s matcher through the candidates `cand` (module doc, 2-4), its differences made
    from the descriptors (the ``ivf`` index's path; `search_rows` reads them from the rows
    instead); `root`: the differences are L2 distances (``distance=euclidean``), else squared
    ones (Eq. 4)."""
    q, db = _descriptors(queries, database)
    nq, ndb = len(q), len(db)
    if cand.index.shape[0] != nq:
        raise DataError(f"candidates for {cand.index.shape[0]} queries, but {nq} queries")
    limit = db_limits(db_limit, nq, ndb)
    window = window_of(config, enhance_window)
    head, tail = _setting(config, window)
    centre = db.mean(axis=0, dtype=np.float64)
    dbc = np.ascontiguousarray(db - centre, dtype=np.float32)
    qc = np.ascontiguousarray(q - centre, dtype=np.float32)
    dbn = np.einsum("ij,ij->i", dbc, dbc, dtype=np.float64)
    *found, low = _kernel(qc, dbc, dbn, _NO_ROWS, 0, 0, nq, nq, ndb,
                          np.ascontiguousarray(cand.index), *head, limit, *tail, root)
    return finish(config, tuple(found), _shift(config, low), ndb, window)


def search_rows(rows: Callable[[int, int], np.ndarray], n_queries: int, n_database: int, k: int,
                configs: Sequence[MatcherConfig], *, db_limit: np.ndarray | None = None,
                windows: Sequence[int | None] | None = None, block: int | None = None,
                ) -> tuple[Candidates, list[MatchResult], list[float]]:
    """The ``flat`` index and the search through it in one pass over the difference matrix
    whose rows ``[a, b)`` ``rows(a, b)`` returns, `block` rows at a time (module doc, 1 and 3):
    each query's `k` lowest differences in its own row are its candidates, and every setting
    of `configs` searches them on those rows. Holds one block and the trajectories' rows
    before and after it, never the whole matrix. Returns the candidates, the results, and per
    setting the seconds spent: computing the rows and choosing the candidates (shared, counted
    to each) and its own search. With no settings, the candidates alone (`nearest`). `block`:
    when None, as many rows as two copies of a block fit in the memory budget (the block's and
    the held ones, `safl_bench.matching.blocks.block_rows`)."""
    nq, ndb = blocks._shape(n_queries, n_database)
    k = check_k(k, ndb)
    limit = db_limits(db_limit, nq, ndb)
    step = blocks._step(nq, ndb, block, copies=2)
    chosen = [(w, *_setting(c, w)) for c, w in
              zip(configs, blocks._windows(configs, windows), strict=True)]
    reach = [c.u_range() for c in configs]
    cand_i = np.full((nq, k), -1, np.int64)
    cand_d = np.full((nq, k), np.inf)
    held: np.ndarray = np.empty((0, ndb), np.float32)
    held_lo = 0
    done = [0] * len(configs)
    found: list[list[tuple[np.ndarray, ...]]] = [[] for _ in configs]
    shared, own = 0.0, [0.0] * len(configs)
    for a in range(0, nq, step):
        b = min(a + step, nq)
        t0 = time.perf_counter()
        raw: np.ndarray = np.asarray(rows(a, b))
        if raw.shape != (b - a, ndb):
            raise DataError(f"rows {a}..{b - 1} of the difference matrix have shape {raw.shape}, "
                            f"expected ({b - a}, {ndb})")
        try:
            raw = _as_difference(raw, np.float32 if raw.dtype == np.float32 else np.float64)
        except DataError as exc:
            raise DataError(f"rows {a}..{b - 1}: {exc}") from None
        cand_i[a:b], cand_d[a:b] = _nearest_rows(raw, limit[a:b], k)
        held = raw if not len(held) else np.concatenate([held.astype(raw.dtype, copy=False), raw])
        shared += time.perf_counter() - t0
        for s, (_, head, tail) in enumerate(chosen):
            t0 = time.perf_counter()
            end = nq if b == nq else min(nq, max(done[s], b - reach[s][1]))
            if end > done[s]:
                out = _kernel(_NO_ROWS, _NO_ROWS, _NO_NORMS, held, held_lo, done[s], end, nq,
                              ndb, cand_i, *head, limit, *tail, False)
                found[s].append(out)
                done[s] = end
            own[s] += time.perf_counter() - t0
        first_read = min((max(0, d + r[0]) for d, r in zip(done, reach, strict=True)),
                         default=b)
        if first_read > held_lo:  # the rows no query left to search reads
            held = held[first_read - held_lo:].copy()
            held_lo = first_read
    results = []
    for cfg, (window, _, _), parts in zip(configs, chosen, found, strict=True):
        cols = [np.concatenate([p[m] for p in parts]) for m in range(6)]
        results.append(finish(cfg, tuple(cols[:5]), _shift(cfg, cols[5]), ndb, window))
    return Candidates(cand_i, cand_d), results, [shared + x for x in own]


#: The kernel's "no rows" (its differences made from descriptors) and "no descriptors".
_NO_ROWS = np.empty((0, 0), np.float32)
_NO_NORMS = np.empty(0)


def _setting(config: MatcherConfig, window: int,
             ) -> tuple[tuple[np.ndarray, int, bool, bool], tuple[int, int, int]]:
    """The kernel's arguments for `config` with enhancement window `window`: those between the
    candidates and the limits (offsets, u_lo, the edge and out-of-range rules), and those
    after (the ratio half-window, the enhancement's reach before and after a frame)."""
    before, after = ((window // 2, window // 2) if config.enhance_mode == "centred"
                     else (window, 0)) if window > 0 else (0, 0)
    return ((config.offsets(), config.u_range()[0], config.edge_queries == "skip",
             config.out_of_range == "clip"), (config.ratio_window // 2, before, after))


def _shift(config: MatcherConfig, low: np.ndarray) -> float:
    """The shift (module doc, 4): the lowest enhanced value read, 0 when none or unshifted."""
    if not config.shift:
        return 0.0
    seen = low[np.isfinite(low)]
    return float(seen.min()) if seen.size else 0.0


@numba.njit(parallel=True, cache=True)
def _nearest_rows(D, limit, k):
    """Per row i: its `k` lowest values among frames ``0 .. limit[i] - 1`` (ties: the lower
    frame), in ascending frame order, -1 and +inf padding a row with fewer frames."""
    n = D.shape[0]
    idx = np.full((n, k), -1, np.int64)
    dist = np.full((n, k), np.inf)
    for i in numba.prange(n):
        m = min(limit[i], k)
        bi = np.empty(k, np.int64)
        bv = np.empty(k)
        if k > _INSERT_K:  # a stable sort: the lowest k, equal values in frame order
            order = np.argsort(D[i, :limit[i]], kind="mergesort")[:m]
            for x in range(m):
                bi[x] = order[x]
                bv[x] = D[i, order[x]]
        else:  # k kept in a sorted list; an equal value never displaces an earlier frame
            cnt = 0
            for j in range(limit[i]):
                v = float(D[i, j])
                if cnt < k:
                    p = cnt
                    cnt += 1
                elif v < bv[k - 1]:
                    p = k - 1
                else:
                    continue
                while p > 0 and bv[p - 1] > v:
                    bv[p] = bv[p - 1]
                    bi[p] = bi[p - 1]
                    p -= 1
                bv[p] = v
                bi[p] = j
        order = np.argsort(bi[:m])
        for x in range(m):
            idx[i, x] = bi[order[x]]
            dist[i, x] = bv[order[x]]
    return idx, dist


#: Up to this many candidates a row keeps them in a sorted list as it reads it; beyond, it sorts.
_INSERT_K = 32


@numba.njit(cache=True, fastmath=True)
def _tile(q, r0, r1, r2, r3, db, c0, c1, c2, c3, out, j):
    """``out[i, j + m]`` = the float32 dot product of query row ``r<i>`` and database row
    ``c<m>``, for i, m in 0..3: 16 products at once, so that each element read serves four of
    them (module doc, 3). Every product of the kernel is made here, each of the 16 the same
    way, so a (row, frame) pair gets the same bits whichever tile computes it (test)."""
    f = numba.float32
    s00, s01, s02, s03 = f(0.0), f(0.0), f(0.0), f(0.0)
    s10, s11, s12, s13 = f(0.0), f(0.0), f(0.0), f(0.0)
    s20, s21, s22, s23 = f(0.0), f(0.0), f(0.0), f(0.0)
    s30, s31, s32, s33 = f(0.0), f(0.0), f(0.0), f(0.0)
    a0, a1, a2, a3 = q[r0], q[r1], q[r2], q[r3]
    b0, b1, b2, b3 = db[c0], db[c1], db[c2], db[c3]
    for x in range(a0.shape[0]):
        x0, x1, x2, x3 = a0[x], a1[x], a2[x], a3[x]
        y0, y1, y2, y3 = b0[x], b1[x], b2[x], b3[x]
        s00 += x0 * y0
        s01 += x0 * y1
        s02 += x0 * y2
        s03 += x0 * y3
        s10 += x1 * y0
        s11 += x1 * y1
        s12 += x1 * y2
        s13 += x1 * y3
        s20 += x2 * y0
        s21 += x2 * y1
        s22 += x2 * y2
        s23 += x2 * y3
        s30 += x3 * y0
        s31 += x3 * y1
        s32 += x3 * y2
        s33 += x3 * y3
    out[0, j], out[0, j + 1], out[0, j + 2], out[0, j + 3] = s00, s01, s02, s03
    out[1, j], out[1, j + 1], out[1, j + 2], out[1, j + 3] = s10, s11, s12, s13
    out[2, j], out[2, j + 1], out[2, j + 2], out[2, j + 3] = s20, s21, s22, s23
    out[3, j], out[3, j + 1], out[3, j + 2], out[3, j + 3] = s30, s31, s32, s33


@numba.njit(parallel=True, cache=True, error_model="numpy")
def _kernel(q, db, dbn, D, row0, t0, t1, nq, ndb, cand, offs, u_lo, skip_edges, clip, limit,
            half, before, after, root):
    """The search of queries ``t0 .. t1 - 1`` of `nq` (module doc, 2-4). Its differences are
    read from the rows `D` (row r of the whole matrix is ``D[r - row0]``) when it has any, else
    made from the centred descriptors `q`, `db` (norms `dbn`; `root`: their L2 root)."""
    from_rows = D.shape[0] > 0
    nv, L = offs.shape
    kc = cand.shape[1]
    n_out = t1 - t0
    index = np.full(n_out, -1, dtype=np.int64)
    best_s = np.full(n_out, np.inf)
    second = np.full(n_out, np.inf)
    vel = np.full(n_out, -1, dtype=np.int64)
    n_terms = np.zeros(n_out, dtype=np.int64)
    low = np.full(n_out, np.inf)
    enhance = before + after > 0
    # the widest union of frames a group of four points reads, plus a tile's padding
    spread = 0
    for k in range(L):
        for k2 in range(k, min(k + 4, L)):
            for vi in range(nv):
                for vi2 in range(nv):
                    spread = max(spread, abs(offs[vi, k] - offs[vi2, k2]))
    width = min(ndb, spread + before + after + 1) + 3
    qns = np.zeros(q.shape[0])
    for r in numba.prange(q.shape[0]):
        qn = 0.0
        for x in range(q.shape[1]):
            qn += float(q[r, x]) * float(q[r, x])
        qns[r] = qn
    for T in numba.prange(t0, t1):
        o = T - t0
        k0 = max(0, -T - u_lo)
        k1 = min(L, nq - T - u_lo)
        cnt = k1 - k0
        n_terms[o] = cnt
        jend = limit[T]
        if (skip_edges and cnt < L) or jend <= 0:
            continue
        sums = np.full((kc, nv), np.inf)
        prod = np.empty((4, width if not from_rows else 0), np.float32)
        d = np.empty(width)
        lo = np.empty(4, np.int64)
        hi = np.empty(4, np.int64)
        for ci in range(kc):
            j = cand[T, ci]
            if j < 0 or j >= jend:
                continue
            for vi in range(nv):
                inside = True
                if not clip:
                    for k in range(k0, k1):
                        c = j + offs[vi, k]
                        if c < 0 or c >= ndb:
                            inside = False
                            break
                if inside:
                    sums[ci, vi] = 0.0
        lowest = np.inf
        # candidate by candidate, its trajectory points four at a time (module doc, 3)
        for ci in range(kc):
            j = cand[T, ci]
            if j < 0 or j >= jend:
                continue
            alive = False
            for vi in range(nv):
                alive = alive or sums[ci, vi] < np.inf
            if not alive:
                continue
            for g0 in range(k0, k1, 4):
                g1 = min(g0 + 4, k1)
                for k in range(g0, g1):
                    cmin = ndb
                    cmax = -1
                    for vi in range(nv):
                        if sums[ci, vi] < np.inf:
                            c = min(max(j + offs[vi, k], 0), ndb - 1)
                            cmin = min(cmin, c)
                            cmax = max(cmax, c)
                    lo[k - g0] = max(0, cmin - before)
                    hi[k - g0] = min(ndb, cmax + after + 1)
                ga = lo[0]
                gb = hi[0]
                for i in range(1, g1 - g0):
                    ga = min(ga, lo[i])
                    gb = max(gb, hi[i])
                rr = T + u_lo + g0
                rl = T + u_lo + g1 - 1  # padding rows repeat the group's last row
                if not from_rows:
                    for cc in range(ga, gb, 4):
                        _tile(q, rr, min(rr + 1, rl), min(rr + 2, rl), min(rr + 3, rl),
                              db, cc, min(cc + 1, ndb - 1), min(cc + 2, ndb - 1),
                              min(cc + 3, ndb - 1), prod, cc - ga)
                for k in range(g0, g1):
                    r = T + u_lo + k
                    a = lo[k - g0]
                    b = hi[k - g0]
                    if from_rows:
                        for c in range(a, b):
                            d[c - a] = D[r - row0, c]
                    else:
                        qn = qns[r]
                        for c in range(a, b):
                            v = max(qn + dbn[c] - 2.0 * float(prod[k - g0, c - ga]), 0.0)
                            d[c - a] = np.sqrt(v) if root else v
                    floor = 0.0
                    if enhance:
                        m = 0.0
                        for x in range(b - a):
                            m += d[x]
                        m /= b - a
                        s2 = 0.0
                        for x in range(b - a):
                            s2 += (d[x] - m) ** 2
                        floor = 1e-12 * s2 / (b - a)
                    seen_c = -1  # velocities that meet at one frame share its value
                    seen_z = 0.0
                    for vi in range(nv):
                        if sums[ci, vi] == np.inf:
                            continue
                        c = min(max(j + offs[vi, k], 0), ndb - 1)
                        if c == seen_c:
                            sums[ci, vi] += seen_z
                            continue
                        z = d[c - a]
                        if enhance:
                            wa = max(0, c - before)
                            wb = min(ndb, c + after + 1)
                            w = wb - wa
                            if w < 2:
                                z = 0.0
                            else:
                                mu = 0.0
                                for x in range(wa - a, wb - a):
                                    mu += d[x]
                                mu /= w
                                var = 0.0
                                for x in range(wa - a, wb - a):
                                    var += (d[x] - mu) ** 2
                                var /= w - 1
                                z = (d[c - a] - mu) / np.sqrt(var) if var > floor else 0.0
                        sums[ci, vi] += z
                        lowest = min(lowest, z)
                        seen_c = c
                        seen_z = z
        low[o] = lowest
        cstar = -1
        vstar = -1
        bval = np.inf
        per = np.full(kc, np.inf)
        for ci in range(kc):
            for vi in range(nv):
                if sums[ci, vi] < per[ci]:
                    per[ci] = sums[ci, vi]
                    if per[ci] < bval:
                        bval = per[ci]
                        cstar = ci
                        vstar = vi
            # a later velocity of the same candidate wins only when strictly lower (above);
            # a later candidate only when strictly lower than every earlier one: lowest j
        if cstar >= 0:
            jstar = cand[T, cstar]
            # the velocity: the first one reaching this candidate's minimum
            for vi in range(nv):
                if sums[cstar, vi] == per[cstar]:
                    vstar = vi
                    break
            index[o] = jstar
            best_s[o] = bval / cnt
            vel[o] = vstar
            sv = np.inf
            for ci in range(kc):
                j = cand[T, ci]
                if j >= 0 and abs(j - jstar) > half and per[ci] < sv:
                    sv = per[ci]
            second[o] = sv / cnt
    return index, best_s, second, vel, n_terms, low


def candidate_ranks(cand: Candidates, true_places: list[np.ndarray], not_found: int) -> np.ndarray:
    """(Nq,) int64: per query the 1-based rank of its nearest true place among its candidates
    by the index's distance (ties: lower frame first), `not_found` when none of its true
    places is a candidate, 0 for a query without a true place (module doc, 5)."""
    ranks = np.zeros(len(true_places), np.int64)
    for i, js in enumerate(true_places):
        if len(js) == 0:
            continue
        row_i, row_d = cand.index[i], cand.distance[i]
        hit = np.isin(row_i, js) & (row_i >= 0)
        if not hit.any():
            ranks[i] = not_found
            continue
        h = np.flatnonzero(hit)
        b = h[np.argmin(row_d[h])]  # the first minimum: rows are in ascending frame order
        nearer = (row_d < row_d[b]) | ((row_d == row_d[b]) & (row_i < row_i[b]))
        ranks[i] = int(np.count_nonzero(nearer & (row_i >= 0))) + 1
    return ranks
