"""Plain-loop reference implementation of the matcher's equations (slow: O(Nq Ndb V ds)).

Written independently of the vectorised kernels in `safl_bench.matching.matcher`, straight from the
definitions in its module docstring; the tests check that both agree and the benchmark reports the
speed ratio. Not for real use.
"""

from __future__ import annotations

import math

import numpy as np

from safl_bench.matching.matcher import MatcherConfig


def ref_enhance(D: np.ndarray, window: int, mode: str) -> np.ndarray:
    """Eq. 5 written as loops: z-score of D[i, j] within its database window."""
    nq, ndb = D.shape
    out = np.zeros((nq, ndb))
    before, after = (window // 2, window // 2) if mode == "centred" else (window, 0)
    for i in range(nq):
        rowvar = np.var(D[i])
        for j in range(ndb):
            w = D[i, max(0, j - before): min(ndb, j + after + 1)].astype(np.float64)
            if len(w) < 2:
                continue
            var = np.var(w, ddof=1)
            if var <= 1e-12 * rowvar or var <= 0:
                continue
            out[i, j] = (D[i, j] - w.mean()) / math.sqrt(var)
    return out


def ref_match(
    D: np.ndarray, cfg: MatcherConfig, db_limit: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 6-7 as loops over queries, candidates, velocities and trajectory points."""
    nq, ndb = D.shape
    Dh = ref_enhance(D, cfg.enhance_window, cfg.enhance_mode) if cfg.enhance_window else D.copy()
    Dh = Dh - Dh.min()
    vels = cfg.velocities()
    u_lo, u_hi = cfg.u_range()
    limit = np.full(nq, ndb) if db_limit is None else db_limit
    S = np.full((nq, ndb), np.inf)
    index = np.full(nq, -1)
    score = np.full(nq, np.inf)
    velocity = np.full(nq, np.nan)
    for T in range(nq):
        rows = [T + u for u in range(u_lo, u_hi + 1) if 0 <= T + u < nq]
        if cfg.edge_queries == "skip" and len(rows) < cfg.ds + 1:
            continue
        bestv = {}
        for j in range(limit[T]):
            for v in vels:
                total, ok = 0.0, True
                for u in range(u_lo, u_hi + 1):
                    r = T + u
                    if not 0 <= r < nq:
                        continue
                    c = j + math.floor(round(v * u, 9) + 0.5)
                    if not 0 <= c < ndb:
                        if cfg.out_of_range == "exclude":
                            ok = False
                            break
                        c = min(max(c, 0), ndb - 1)
                    total += Dh[r, c]
                if ok and total / len(rows) < S[T, j]:
                    S[T, j] = total / len(rows)
                    bestv[j] = v
        if limit[T] == 0 or not np.isfinite(S[T]).any():
            continue
        j = int(np.argmin(S[T]))
        index[T], velocity[T] = j, bestv[j]
        if cfg.score == "min":
            score[T] = S[T, j]
        else:
            others = [S[T, k] for k in range(ndb) if abs(k - j) > cfg.ratio_window // 2]
            second = min(others, default=np.inf)
            score[T] = S[T, j] / second if np.isfinite(second) and second > 0 else 1.0
    return index, score, velocity, S
