"""Candidate search: the sequence matcher through each query's k nearest database frames only,
in the spirit of Fast-SeqSLAM (Siam and Zhang, ICRA 2017), which searches sequences through
each query's approximate nearest neighbours instead of the whole difference matrix.

Opt-in (the evaluation settings ``candidates=K`` and ``index=flat|ivf``; records carry both, so
tables never mix its cells with the exact matcher's: their preset label differs). The exact
matcher (`safl_bench.matching.matcher`, in blocks: `safl_bench.matching.blocks`) stays the
definition; this mode approximates it, and `docs/reference/speed.md` gives its measured
accuracy cost. What it does, with the choices Fast-SeqSLAM's idea leaves open:

1. Candidates. An index over the database descriptors gives each query row its `k` nearest
   frames by L2 (FAISS: ``flat`` = exact search, ``IndexFlatL2``; ``ivf`` = approximate,
   ``IndexIVFFlat`` with `ivf_lists` lists, `IVF_PROBE` of them searched, k-means with FAISS's
   fixed seed, so the same candidates every run). With a ``db_limit`` (the revisit protocol),
   only frames ``j < db_limit[T]`` are candidates of T: queries are searched in groups of
   `GROUP` with a range selector up to the group's largest limit and ``k`` plus the spread of
   the group's limits neighbours, so that after dropping each query's forbidden frames it
   still holds its k nearest allowed ones (exactly, for the ``flat`` index).
2. The reported frame of query T is one of T's own candidates: ``S(T, j, V)`` (module doc of
   the matcher, 2-5: the same trajectories, velocities, edge and out-of-range rules) is
   evaluated for ``j`` in T's candidates only, and the match is the lowest (ties: lowest
   velocity, then lowest j, the one tie rule). This is where the accuracy is lost: a true
   match whose single frame is not among the k nearest cannot be reported, however well its
   sequence agrees.
3. The values the trajectories read are exact: each point's difference is computed from the
   descriptors (Eq. 4's squared L2, or its root for ``distance=euclidean``), and the contrast
   enhancement (Eq. 5) of a point uses the differences of its whole window, computed too. So
   with ``k`` = the whole database this mode finds the exact matcher's matches up to
   floating-point rounding (it computes in float64, per point, not the float32 BLAS product).
4. What it cannot see of the whole matrix, it takes from what it computed: the shift that
   makes S non-negative (``shift=True``) is the lowest enhanced value it read (the ranking by
   the paper's ``min`` score does not depend on it), a window's zero-spread floor is 1e-12 of
   the spread of the differences computed for that point's row and candidate, and the ratio
   score's second-best S is the best over the other candidates outside the ratio window (1.0,
   no evidence, when there is none).
5. The single-frame answer is the nearest candidate; a query's true place that is not among
   its candidates is ranked at no N (`safl_bench.methods.retrieval.NOT_RETRIEVED`), as for a
   retrieval method that did not return it.

Only descriptors compared by L2 can be searched so: a method with its own distance
(`Method.distance` overridden: SAD's L1, Scan Context's shifted cosine) is a ConfigError unless
the cell's ``distance=euclidean`` says to compare its descriptors by L2.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from safl_bench.errors import ConfigError, DataError
from safl_bench.matching.matcher import (
    MatcherConfig,
    MatchResult,
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
    index's L2 distance (squared) to each (+inf on padding)."""

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
            db_limit: np.ndarray | None = None) -> Candidates:
    """The `k` nearest database frames of each query by L2 (module doc, 1)."""
    if index not in INDEXES:
        raise ConfigError(f"index must be one of {', '.join(map(repr, INDEXES))}, got {index!r}")
    q, db = _descriptors(queries, database)
    nq, ndb = len(q), len(db)
    k = check_k(k, ndb)
    limit = db_limits(db_limit, nq, ndb)
    faiss = faiss_module()
    centre = db.mean(axis=0, dtype=np.float64)
    dbc = np.ascontiguousarray(db - centre, dtype=np.float32)
    qc = np.ascontiguousarray(q - centre, dtype=np.float32)
    dim = db.shape[1]
    probe: dict[str, Any] = {}
    if index == "flat":
        ix = faiss.IndexFlatL2(dim)
    else:
        lists = ivf_lists(ndb)
        ix = faiss.IndexIVFFlat(faiss.IndexFlatL2(dim), dim, lists)
        ix.train(dbc)
        probe = {"nprobe": min(IVF_PROBE, lists)}
    ix.add(dbc)
    out_i = np.full((nq, k), -1, np.int64)
    out_d = np.full((nq, k), np.inf)
    if db_limit is None:
        params = faiss.SearchParametersIVF(**probe) if probe else None
        dist, idx = ix.search(qc, k, params=params)
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
            params = (faiss.SearchParametersIVF(sel=sel, **probe) if probe
                      else faiss.SearchParameters(sel=sel))
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
    """`config`'s matcher through the candidates `cand` (module doc, 2-4); `root`: the
    differences are L2 distances (``distance=euclidean``), else squared ones (Eq. 4)."""
    q, db = _descriptors(queries, database)
    nq, ndb = len(q), len(db)
    if cand.index.shape[0] != nq:
        raise DataError(f"candidates for {cand.index.shape[0]} queries, but {nq} queries")
    limit = db_limits(db_limit, nq, ndb)
    window = window_of(config, enhance_window)
    before, after = ((window // 2, window // 2) if config.enhance_mode == "centred"
                     else (window, 0)) if window > 0 else (0, 0)
    centre = db.mean(axis=0, dtype=np.float64)
    dbc = np.ascontiguousarray(db - centre, dtype=np.float32)
    qc = np.ascontiguousarray(q - centre, dtype=np.float32)
    dbn = np.einsum("ij,ij->i", dbc, dbc, dtype=np.float64)
    offs = config.offsets()
    u_lo, _ = config.u_range()
    index, best, second, vel, n_terms, low = _kernel(
        qc, dbc, dbn, np.ascontiguousarray(cand.index), offs, u_lo,
        config.edge_queries == "skip", config.out_of_range == "clip", limit,
        config.ratio_window // 2, before, after, root)
    shift = 0.0
    if config.shift:
        seen = low[np.isfinite(low)]
        shift = float(seen.min()) if seen.size else 0.0
    return finish(config, (index, best, second, vel, n_terms), shift, ndb, window)


@numba.njit(cache=True, fastmath=True)
def _dot(a, b):
    s = numba.float32(0.0)
    for x in range(a.shape[0]):
        s += a[x] * b[x]
    return s


@numba.njit(parallel=True, cache=True, error_model="numpy")
def _kernel(q, db, dbn, cand, offs, u_lo, skip_edges, clip, limit, half, before, after, root):
    nq = q.shape[0]
    ndb = db.shape[0]
    nv, L = offs.shape
    kc = cand.shape[1]
    index = np.full(nq, -1, dtype=np.int64)
    best_s = np.full(nq, np.inf)
    second = np.full(nq, np.inf)
    vel = np.full(nq, -1, dtype=np.int64)
    n_terms = np.zeros(nq, dtype=np.int64)
    low = np.full(nq, np.inf)
    enhance = before + after > 0
    for T in numba.prange(nq):
        k0 = max(0, -T - u_lo)
        k1 = min(L, nq - T - u_lo)
        cnt = k1 - k0
        n_terms[T] = cnt
        jend = limit[T]
        if (skip_edges and cnt < L) or jend <= 0:
            continue
        sums = np.full((kc, nv), np.inf)
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
        for k in range(k0, k1):
            r = T + u_lo + k
            qr = q[r]
            qn = 0.0
            for x in range(qr.shape[0]):
                qn += float(qr[x]) * float(qr[x])
            for ci in range(kc):
                j = cand[T, ci]
                if j < 0 or j >= jend:
                    continue
                cmin = ndb
                cmax = -1
                for vi in range(nv):
                    if sums[ci, vi] < np.inf:
                        c = min(max(j + offs[vi, k], 0), ndb - 1)
                        cmin = min(cmin, c)
                        cmax = max(cmax, c)
                if cmax < 0:
                    continue
                a = max(0, cmin - before)
                b = min(ndb, cmax + after + 1)
                d = np.empty(b - a)
                for c in range(a, b):
                    v = max(qn + dbn[c] - 2.0 * float(_dot(qr, db[c])), 0.0)
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
                for vi in range(nv):
                    if sums[ci, vi] == np.inf:
                        continue
                    c = min(max(j + offs[vi, k], 0), ndb - 1)
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
        low[T] = lowest
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
            index[T] = jstar
            best_s[T] = bval / cnt
            vel[T] = vstar
            sv = np.inf
            for ci in range(kc):
                j = cand[T, ci]
                if j >= 0 and abs(j - jstar) > half and per[ci] < sv:
                    sv = per[ci]
            second[T] = sv / cnt
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
