"""The shared matcher: SeqSLAM sequence matching (paper §II.D, Eq. 5-7, Table I) and the
single-frame baseline, vectorised (numba kernels, parallel over queries).

Orientation: the input difference matrix ``D`` has shape (Nq, Ndb), row = query frame, column =
database frame, LOWER = more similar. ``MatchResult.score`` is also lower = better; metrics want a
confidence (higher = better) and get it from `safl_bench.matching.confidence.confidence_from_score`, the one
place where the sign is flipped (``MatchResult.confidence`` calls it).

Definition followed (the paper's, with the choices it leaves open written down). The defaults
are the paper's; `safl_bench.matching.presets` names whole sets of these settings ("paper",
"authors": the authors' public code, "openseqslam") and says where each value comes from.

1. Local contrast enhancement (Eq. 5), along the database axis, per query row ``i``::

       Dhat[i, j] = (D[i, j] - mean(D[i, W(j)])) / std(D[i, W(j)], ddof=1)

   with ``W(j) = [j - R//2, j + R//2]`` clipped to the database ("centred", as OpenSeqSLAM, whose
   paper [8] the authors cite for this step) or ``[j - R, j]`` ("causal", option),
   ``R = enhance_window`` (0 disables). ``enhance_rule="dip"`` takes R from the data instead:
   from the width of the dip in the DATABASE's own self-difference, measured per cell with the
   cell's distance, no ground truth and no score involved (`safl_bench.matching.window`, whose
   docstring argues the rule and its constants); ``match`` is then given that R
   (``enhance_window=`` argument) and ``enhance_window`` must be 0. The ``paper`` preset uses
   the rule; ``paper-r10`` keeps OpenSeqSLAM's fixed 10 frames, which on these tasks (every 4th
   frame, 60-80 m views) lie inside the true match's own dip. A window of one frame (causal, j = 0) or a window with (numerically) zero spread, i.e. variance
   <= 1e-12 x the variance of the whole row, gives ``Dhat = 0``. Then, as in OpenSeqSLAM, the
   whole enhanced matrix is shifted so that its minimum is 0 (``shift=True``, default: this
   does not change any match and makes S >= 0, which the ratio score needs). ``shift=False``
   keeps the z-scores as they are, so S is negative for a good match (the authors' code, whose
   ``enhanceContrast`` has the shift commented out); it matters only to the ``"inverse"`` and
   ``"ratio"`` scores. `enhanced_matrix` returns exactly the matrix the search reads.
2. Sequence search (Eq. 6-7). For query ``T`` and candidate database frame ``j`` (the frame
   reported as the match of ``T``), a straight trajectory at velocity ``V`` visits, for each query
   row ``T + u``, the database column ``j + round(V u)`` (round half up). The paper's trajectory
   looks back: ``u = -ds .. 0``, i.e. ``ds + 1`` queries ending at ``T`` (``trajectory="causal"``,
   default). OpenSeqSLAM centres it on ``T``: ``u = -(ds - ds//2) .. ds//2``
   (``trajectory="centred"``, option; needs future queries). The paper's Eq. 7 prints
   ``k = s - V(d_s - T + t)``; the minus sign would run the database backwards while the queries
   run forwards and is taken as a typo of Milford & Wyeth's ``+``.
   ``offset_rounding="floor_start"`` (option; OpenSeqSLAM's and the authors' code) anchors the
   trajectory at its FIRST query instead: its k-th point (k = 0 .. ds) lies at database frame
   ``j0 + floor(V k)`` (computed as ``floor(k * V)`` in float64), and the frame reported is
   ``j0 + (number of trajectory queries before T)`` (``j0 + ds/2`` for the centred trajectory)
   whatever V is, so at V != 1 the reported frame need not be the point the trajectory visits
   at ``T``. The default ``"half_up"`` is the definition above, symmetric about ``T``.
   ``S(T, j, V)`` is the MEAN of ``Dhat`` over the trajectory's points: for a full trajectory
   this is the paper's sum divided by the constant ``ds + 1`` (same ranking), and it keeps
   shortened trajectories (below) on the same scale. ``S(T, j) = min_V S(T, j, V)``, and the
   match of ``T`` is ``argmin_j S(T, j)`` (ties: lowest velocity, then lowest ``j``: the
   one tie rule of `safl_bench.evaluation.metrics`, which its Recall@N ranks follow in the same dtype).
3. Velocities: ``V_min, V_min + V_step, ..., V_max`` computed as ``round(V_min + k V_step, 9)``
   (no accumulated steps). The paper's Table I lists V from 0.8 to 1.1 by 0.1, four velocities,
   so ``V_max`` is included (``v_inclusive=True``, default). The authors' public code
   (``getMatches`` in src/util/utils.py) and OpenSeqSLAM take ``int(vmin ds) .. int(vmax ds)``
   (inclusive) divided by ``ds``, with vmax = 1.2 (parameters.py; OpenSeqSLAM's default too):
   five velocities, 0.8 to 1.2, i.e. ``v_max=1.2`` here (the same floats, since
   ``round(0.8 + 0.1 k, 9)`` and ``(8 + k) / 10`` are the same doubles).
4. Queries near the ends of the query sequence (``T < ds`` for the causal trajectory) have fewer
   than ``ds + 1`` rows: ``edge_queries="shorten"`` (default) uses the rows that exist (mean over
   them; ``n_terms`` records how many, ``complete`` flags full ones); ``edge_queries="skip"``
   reports no match for them (index -1, score +inf); with the centred trajectory these are the
   first ``ds - ds//2`` and the last ``ds//2`` queries (OpenSeqSLAM and the authors' code).
   CONSEQUENCE of "shorten": a mean over fewer rows spreads wider, so its minimum over the
   database lies lower and the first queries are a cell's most confident answers, right or
   wrong; under task versions that scored them, the most confident wrong match was one of
   queries 0-9 in almost every paper-protocol sequence cell, so it alone set recall at 100 %
   precision (docs/reference/tasks.md, "Context queries", gives the before/after table
   computed from the records). The matcher keeps "shorten" as the paper preset's setting; the
   paper and BEVPlace tasks (synthetic v5, KITTI and top-view v1) make their first d_s = 10
   queries context (`TaskSpec.context_queries`: matched, never scored), so no scored query of
   the default preset has a shortened trajectory.
5. Trajectory points whose database column falls outside ``[0, Ndb)``:
   ``out_of_range="exclude"`` (default, as OpenSeqSLAM, which pads with +inf) drops that
   (j, V) candidate; ``"clip"`` reads the first/last column instead.
6. Score: ``score="min"`` (default, the paper: a loop closure is declared when S is below a
   threshold) is ``S(T, j*)``; ``score="ratio"`` (OpenSeqSLAM) is ``S(T, j*)`` over the lowest
   ``S(T, j)`` with ``|j - j*| > ratio_window // 2``, in [0, 1], comparable across queries; it is
   1.0 (no evidence) when there is no such j or that S is 0 (it assumes S >= 0: ``shift=True``).
   ``score="inverse"`` (the authors' code) ranks queries by ``min(1 / S_sum, 1)``, with
   ``S_sum`` the trajectory's SUM (``S(T, j*)`` times the points used); ``MatchResult.score``
   is its negative (lower = better). QUIRK, kept on purpose: without the shift a strong match
   has a negative S, hence a negative 1/S, and ranks below every positive S, the weakest matches
   included; and every S in [0, 1) is capped to the same top confidence 1. QUIRK 2,
   ``capped_match`` (``score="inverse"`` only; default None): the authors' code sets the whole
   answer to 1.0 when it caps (``match = 1.0`` assigns the frame column as well), so a capped
   query reports database frame 1; ``capped_match=1`` reproduces that (must be < Ndb).
7. ``db_limit`` (optional, per query): only database frames ``j < db_limit[T]`` may be reported
   as the match (the revisit protocol's "older than a time window"); the trajectory's earlier
   points lie at lower j anyway. Enhancement still uses whole rows. A query with no candidate
   gets index -1 and score +inf.

``preset`` names the preset the settings started from (`safl_bench.matching.presets`); it is
recorded with the other settings and changes no match. Differences from the authors' code that
are NOT settings (no result here depends on them): a window with zero spread gives 0 here, NaN
there; a query with no trajectory inside the database gets no match here, frame ds/2 with
score 0 there.

Single-frame matching is the same machinery with ``ds = 0`` and, by default, no enhancement:
the nearest database frame by the method's difference.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal

import numba
import numpy as np

from safl_bench.errors import ConfigError, DataError
from safl_bench.matching.confidence import confidence_from_score

ScoreKind = Literal["min", "ratio", "inverse"]
SCORES = ("min", "ratio", "inverse")
#: How the contrast-enhancement window is set: ``enhance_window`` itself, or from the
#: database's self-difference (`safl_bench.matching.window`).
ENHANCE_RULES = ("fixed", "dip")
#: What a record made before a setting existed holds for it, where that differs from the
#: dataclass default: records made before ``enhance_rule`` used the fixed window, and their
#: preset name is the one they name (``paper`` then is ``paper-r10`` now: `settings.RENAMED_PRESETS`).
_BEFORE: dict[str, Any] = {"enhance_rule": "fixed"}
#: The preset a record made before ``enhance_rule`` names as ``paper`` (or, before the presets,
#: names none of): the fixed 10-frame window, called ``paper-r10`` since ``paper`` took the rule.
OLD_PAPER = "paper-r10"
_DTYPES = {"float32": np.float32, "float64": np.float64}


@dataclass(frozen=True)
class MatcherConfig:
    """Every setting that changes a match; recorded with each result (`to_dict`).

    The defaults are the paper's (module docstring); the fields after ``dtype`` were added with
    the presets, and a record made before them holds the defaults (`from_dict` fills them in).
    """

    method: Literal["seqslam", "single_frame"] = "seqslam"
    ds: int = 10
    v_min: float = 0.8
    v_max: float = 1.1
    v_step: float = 0.1
    v_inclusive: bool = True
    enhance_window: int = 10
    enhance_mode: Literal["centred", "causal"] = "centred"
    enhance_rule: Literal["fixed", "dip"] = "fixed"
    trajectory: Literal["causal", "centred"] = "causal"
    edge_queries: Literal["shorten", "skip"] = "shorten"
    out_of_range: Literal["exclude", "clip"] = "exclude"
    score: ScoreKind = "min"
    ratio_window: int = 10
    dtype: Literal["float32", "float64"] = "float32"
    shift: bool = True
    offset_rounding: Literal["half_up", "floor_start"] = "half_up"
    capped_match: int | None = None
    preset: str = "paper-r10"

    def __post_init__(self) -> None:
        def bad(msg: str) -> None:
            raise ConfigError(f"matcher config: {msg}")

        if self.method not in ("seqslam", "single_frame"):
            bad(f"method must be 'seqslam' or 'single_frame', got {self.method!r}")
        if not isinstance(self.ds, int | np.integer) or isinstance(self.ds, bool) or self.ds < 0:
            bad(f"ds must be an integer >= 0, got {self.ds!r}")
        if self.method == "single_frame" and self.ds != 0:
            bad(f"single_frame matching has ds = 0, got ds={self.ds}")
        for name in ("v_min", "v_max", "v_step"):
            value = getattr(self, name)
            if not np.isfinite(value):
                bad(f"{name} must be finite, got {value!r}")
        if self.v_step <= 0:
            bad(f"v_step must be > 0, got {self.v_step}")
        if self.v_max < self.v_min:
            bad(f"v_max ({self.v_max}) must be >= v_min ({self.v_min})")
        if self.enhance_window < 0 or (self.enhance_window == 1 and self.enhance_mode == "centred"):
            bad(f"enhance_window must be 0 (off) or >= 2, got {self.enhance_window}")
        if self.enhance_rule not in ENHANCE_RULES:
            bad(f"enhance_rule must be one of {', '.join(map(repr, ENHANCE_RULES))}, "
                f"got {self.enhance_rule!r}")
        if self.enhance_rule == "dip" and self.enhance_window != 0:
            bad(f"enhance_rule='dip' chooses the window from the database, so enhance_window "
                f"must be 0, got {self.enhance_window} (enhance_rule=fixed keeps a fixed window)")
        if self.enhance_rule == "dip" and self.enhance_mode != "centred":
            bad("enhance_rule='dip' measures a window centred on the frame; "
                f"enhance_mode must be 'centred', got {self.enhance_mode!r}")
        if self.enhance_mode not in ("centred", "causal"):
            bad(f"enhance_mode must be 'centred' or 'causal', got {self.enhance_mode!r}")
        if self.trajectory not in ("causal", "centred"):
            bad(f"trajectory must be 'causal' or 'centred', got {self.trajectory!r}")
        if self.edge_queries not in ("shorten", "skip"):
            bad(f"edge_queries must be 'shorten' or 'skip', got {self.edge_queries!r}")
        if self.out_of_range not in ("exclude", "clip"):
            bad(f"out_of_range must be 'exclude' or 'clip', got {self.out_of_range!r}")
        if self.score not in SCORES:
            bad(f"score must be one of {', '.join(map(repr, SCORES))}, got {self.score!r}")
        if self.ratio_window < 0:
            bad(f"ratio_window must be >= 0, got {self.ratio_window}")
        if self.dtype not in _DTYPES:
            bad(f"dtype must be 'float32' or 'float64', got {self.dtype!r}")
        if not isinstance(self.shift, bool | np.bool_):
            bad(f"shift must be true or false, got {self.shift!r}")
        if self.offset_rounding not in ("half_up", "floor_start"):
            bad(f"offset_rounding must be 'half_up' or 'floor_start', got {self.offset_rounding!r}")
        if self.capped_match is not None and (
                not isinstance(self.capped_match, int | np.integer)
                or isinstance(self.capped_match, bool) or self.capped_match < 0):
            bad(f"capped_match must be null (keep the match) or a frame index >= 0, "
                f"got {self.capped_match!r}")
        if not isinstance(self.preset, str) or not self.preset:
            bad(f"preset must be a preset's name, got {self.preset!r}")
        if len(self.velocities()) == 0:
            bad("the velocity grid is empty (v_inclusive=False and v_min == v_max)")

    def velocities(self) -> np.ndarray:
        """The velocity grid, computed without accumulating steps (see module doc, 3)."""
        if self.method == "single_frame" or self.ds == 0:
            return np.array([1.0])
        n = int(np.floor(np.round((self.v_max - self.v_min) / self.v_step, 9)))
        v = np.round(self.v_min + self.v_step * np.arange(n + 1), 9)
        if not self.v_inclusive:
            v = v[v < np.round(self.v_max, 9)]
        return v

    def u_range(self) -> tuple[int, int]:
        """Query offsets (first, last) of a trajectory relative to the query, inclusive."""
        ahead = self.ds // 2 if self.trajectory == "centred" else 0
        return -(self.ds - ahead), ahead

    def offsets(self) -> np.ndarray:
        """(n_velocities, ds + 1) int64: database offset of each trajectory point from j, the
        reported frame (module doc, 2: round half up about T, or floor from the start)."""
        u_lo, u_hi = self.u_range()
        if self.offset_rounding == "floor_start":
            k = np.arange(u_hi - u_lo + 1, dtype=np.float64)
            return (np.floor(k[None, :] * self.velocities()[:, None]) + u_lo).astype(np.int64)
        u = np.arange(u_lo, u_hi + 1, dtype=np.float64)
        vu = np.round(self.velocities()[:, None] * u[None, :], 9)
        return np.floor(vu + 0.5).astype(np.int64)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MatcherConfig:
        """The config a record's settings describe (`to_dict`'s inverse). Settings a record made
        before they existed lacks take their defaults, which is what that code did; an unknown
        setting is a ConfigError naming it."""
        if not isinstance(data, dict):
            raise ConfigError(f"matcher settings must be a mapping, got {data!r}")
        valid = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - valid)
        if unknown:
            raise ConfigError(f"matcher settings: unknown setting(s) {unknown}; valid: {sorted(valid)}")
        # settings older than a field: its value then, where the dataclass default has moved
        if "enhance_rule" not in data and data.get("preset", "paper") == "paper":
            data = {**data, "preset": OLD_PAPER}
        return cls(**{**_BEFORE, **data})

    @property
    def needs_window(self) -> bool:
        """Whether `match` must be given the enhancement window (``enhance_rule="dip"``)."""
        return self.enhance_rule == "dip"


@dataclass
class MatchResult:
    """Per query: the matched database frame and its score (LOWER = better)."""

    index: np.ndarray  # (Nq,) int64, -1 = no match
    score: np.ndarray  # (Nq,) float64, lower = better, +inf = no match
    best_s: np.ndarray  # (Nq,) float64, S(T, j*) after the shift, whatever `score` is
    velocity: np.ndarray  # (Nq,) float64, velocity of the best trajectory (NaN if no match)
    n_terms: np.ndarray  # (Nq,) int64, trajectory points used (ds + 1 when complete)
    complete: np.ndarray  # (Nq,) bool, n_terms == ds + 1
    config: MatcherConfig
    S: np.ndarray | None = field(default=None, repr=False)  # (Nq, Ndb) S(T, j), +inf = none
    #: the contrast-enhancement window used (`window_of`: the config's, or the dip rule's)
    enhance_window: int | None = None

    @property
    def confidence(self) -> np.ndarray:
        """Higher = more confident, for the metrics (`confidence.confidence_from_score`)."""
        return confidence_from_score(self.score)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (without the S matrix); non-finite values become None."""

        def clean(a: np.ndarray) -> list[Any]:
            return [None if not np.isfinite(x) else float(x) for x in a]

        return {
            "config": self.config.to_dict(),
            "index": self.index.tolist(),
            "score": clean(self.score),
            "best_s": clean(self.best_s),
            "velocity": clean(self.velocity),
            "n_terms": self.n_terms.tolist(),
        }


# --------------------------------------------------------------------------- kernels


@numba.njit(parallel=True, cache=True, error_model="numpy")
def _enhance_kernel(D, out, before, after):
    """out[i, j] = (D[i, j] - mean_W) / std_W(ddof=1), W = [j - before, j + after] clipped.

    Window sums from float64 prefix sums of the row minus one of its values (which limits
    cancellation);
    the interior (full windows) is a branch-free loop that vectorises, the edges are separate.
    """
    nq, ndb = D.shape
    for i in numba.prange(nq):
        row = np.empty(ndb)
        for j in range(ndb):
            row[j] = D[i, j]
        m = row[0]  # any value of the row will do as the shift against cancellation
        c1 = np.empty(ndb + 1)
        c2 = np.empty(ndb + 1)
        c1[0] = 0.0
        c2[0] = 0.0
        t1 = 0.0
        t2 = 0.0
        for j in range(ndb):  # scalar running sums: no store-to-load chain through memory
            x = row[j] - m
            row[j] = x
            t1 += x
            t2 += x * x
            c1[j + 1] = t1
            c2[j + 1] = t2
        floor = 1e-12 * max(c2[ndb] / ndb - (c1[ndb] / ndb) ** 2, 0.0)  # x row variance
        # interior: j - before >= 0 and j + after + 1 <= ndb
        j0 = min(before, ndb)
        j1 = max(j0, ndb - after)
        n = before + after + 1
        inv_n = 1.0 / n
        inv_nm1 = 1.0 / (n - 1)
        for j in range(j0, j1):
            s1 = c1[j + after + 1] - c1[j - before]
            mu = s1 * inv_n
            var = (c2[j + after + 1] - c2[j - before] - s1 * mu) * inv_nm1
            ok = var > floor
            out[i, j] = (row[j] - mu) / np.sqrt(var if ok else 1.0) if ok else 0.0
        for j in range(ndb):
            if j0 <= j < j1:
                continue
            a = max(0, j - before)
            b = min(ndb, j + after + 1)
            w = b - a
            if w < 2:
                out[i, j] = 0.0
                continue
            s1 = c1[b] - c1[a]
            mu = s1 / w
            var = (c2[b] - c2[a] - s1 * mu) / (w - 1)
            if var <= floor:
                out[i, j] = 0.0
            else:
                out[i, j] = (row[j] - mu) / np.sqrt(var)


@numba.njit(cache=True, inline="always")
def _cand_range(offs, vi, k0, k1, ndb, jend, clip):
    """Candidates [lo, hi) for velocity vi: all of [0, jend) when clipping, else those whose
    trajectory stays inside the database."""
    if clip:
        return 0, jend
    lo = 0
    hi = ndb
    for k in range(k0, k1):
        o = offs[vi, k]
        lo = max(lo, -o)
        hi = min(hi, ndb - o)
    return lo, min(hi, jend)


@numba.njit(parallel=True, cache=True, error_model="numpy")
def _search_kernel(Dh, offs, u_lo, skip_edges, clip, db_limit, half, keep, S_out,
                   q0, nqb, r0, nq):
    """Queries q0 .. q0 + nqb - 1 of a query sequence of `nq` (outputs indexed from q0); row
    ``r`` of the enhanced matrix is ``Dh[r - r0]`` (the dense path: q0 = r0 = 0, nqb = nq;
    `safl_bench.matching.blocks` passes a block of rows). Every output of query T depends on
    its own rows only, so a block gives bit for bit what the whole matrix gives."""
    ndb = Dh.shape[1]
    nv, L = offs.shape
    index = np.full(nqb, -1, dtype=np.int64)
    best_s = np.full(nqb, np.inf)
    second = np.full(nqb, np.inf)
    vel = np.full(nqb, -1, dtype=np.int64)
    n_terms = np.zeros(nqb, dtype=np.int64)
    for t in numba.prange(nqb):
        T = q0 + t
        k0 = max(0, -T - u_lo)
        k1 = min(L, nq - T - u_lo)
        cnt = k1 - k0
        n_terms[t] = cnt
        jend = db_limit[T]
        best = np.full(ndb, np.inf, dtype=Dh.dtype)
        if (skip_edges and cnt < L) or jend <= 0:
            if keep:
                S_out[t, :] = best
            continue
        acc = np.zeros(ndb, dtype=Dh.dtype)
        for vi in range(nv):
            alo, ahi = _cand_range(offs, vi, k0, k1, ndb, jend, clip)
            if ahi <= alo:
                continue
            acc[alo:ahi] = 0.0
            for k in range(k0, k1):
                o = offs[vi, k]
                r = T + u_lo + k - r0
                lo = max(alo, -o)
                hi = min(ahi, ndb - o)
                if hi > lo:
                    dst = acc[lo:hi]
                    src = Dh[r, lo + o:hi + o]
                    for j in range(hi - lo):
                        dst[j] += src[j]
                if clip:
                    for j in range(alo, min(lo, ahi)):
                        acc[j] += Dh[r, 0]
                    for j in range(max(hi, alo), ahi):
                        acc[j] += Dh[r, ndb - 1]
            # branch-free running minimum of the trajectory SUMS (cnt is the same for all)
            bdst = best[alo:ahi]
            asrc = acc[alo:ahi]
            for j in range(ahi - alo):
                bdst[j] = min(bdst[j], asrc[j])
        jstar = -1
        bval = np.inf
        for j in range(jend):
            if best[j] < bval:
                bval = best[j]
                jstar = j
        if jstar >= 0:
            index[t] = jstar
            best_s[t] = bval / cnt
            # the velocity: first one whose sum at jstar equals the minimum (same additions
            # in the same order as above, so the comparison is exact)
            tot = np.full(nv, np.inf, dtype=Dh.dtype)
            for vi in range(nv):
                alo, ahi = _cand_range(offs, vi, k0, k1, ndb, jend, clip)
                if jstar < alo or jstar >= ahi:
                    continue
                tot[vi] = 0.0
                for k in range(k0, k1):
                    c = min(max(jstar + offs[vi, k], 0), ndb - 1)
                    tot[vi] += Dh[T + u_lo + k - r0, c]
            vel[t] = np.argmin(np.abs(tot - bval))  # first exact match (difference 0)
            sv = np.inf
            for j in range(jend):
                if abs(j - jstar) > half and best[j] < sv:
                    sv = best[j]
            second[t] = sv / cnt
        if keep:
            for j in range(ndb):
                S_out[t, j] = best[j] / cnt
    return index, best_s, second, vel, n_terms


# --------------------------------------------------------------------------- public API


def _as_difference(D: np.ndarray, dtype: Any) -> np.ndarray:
    arr = np.asarray(D)
    if arr.ndim != 2:
        raise DataError(f"difference matrix must be 2-D (queries x database), got shape {arr.shape}")
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise DataError(f"difference matrix is empty (shape {arr.shape})")
    if not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise DataError(f"difference matrix must hold real numbers, got dtype {arr.dtype}")
    arr = np.ascontiguousarray(arr, dtype=dtype)
    if not np.isfinite(arr).all():
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise DataError(f"difference matrix has {bad} NaN or infinite entries")
    return arr


def enhance(D: np.ndarray, window: int = 10, mode: str = "centred", *, dtype: str = "float64",
            out: np.ndarray | None = None) -> np.ndarray:
    """Local contrast enhancement (Eq. 5) along the database axis; not shifted (module doc, 1)."""
    if window < 0 or (window == 1 and mode == "centred"):
        raise ConfigError(f"enhance window must be 0 (off) or >= 2, got {window}")
    if mode not in ("centred", "causal"):
        raise ConfigError(f"enhance mode must be 'centred' or 'causal', got {mode!r}")
    if dtype not in _DTYPES:
        raise ConfigError(f"dtype must be 'float32' or 'float64', got {dtype!r}")
    arr = _as_difference(D, _DTYPES[dtype])
    if out is None:
        out = np.empty_like(arr)
    if window == 0:
        np.copyto(out, arr)
        return out
    before, after = (window // 2, window // 2) if mode == "centred" else (window, 0)
    _enhance_kernel(arr, out, before, after)
    return out


def window_of(cfg: MatcherConfig, enhance_window: int | None = None) -> int:
    """The contrast-enhancement window `cfg` uses: ``enhance_window`` for the fixed rule, the
    one given (chosen from the database, `safl_bench.matching.window.dip_window`) for the
    ``dip`` rule, which needs it (ConfigError without). A window given to a fixed rule that
    differs from its own is a ConfigError too: the record would not say what ran."""
    if cfg.enhance_rule == "dip":
        if enhance_window is None:
            raise ConfigError("matcher config: enhance_rule='dip' takes its window from the "
                              "database (safl_bench.matching.window.dip_window); pass it as "
                              "enhance_window=")
        if not isinstance(enhance_window, int | np.integer) or isinstance(enhance_window, bool) \
                or enhance_window < 2:
            raise ConfigError(f"the dip rule's enhancement window must be an integer >= 2, "
                              f"got {enhance_window!r}")
        return int(enhance_window)
    if enhance_window is not None and enhance_window != cfg.enhance_window:
        raise ConfigError(f"enhance_window={enhance_window} given for a fixed window of "
                          f"{cfg.enhance_window} (enhance_rule='fixed'): set it in the config")
    return cfg.enhance_window


def _enhanced(arr: np.ndarray, cfg: MatcherConfig, given: Any,
              window: int) -> tuple[np.ndarray, float]:
    """(the contrast-enhanced matrix, the shift that makes its minimum 0, or 0.0 without it).
    `arr` is `given` converted; a converted copy is enhanced in place, `given` never is.
    `window`: `window_of(cfg, ...)`."""
    if window > 0:
        before, after = ((window // 2, window // 2)
                         if cfg.enhance_mode == "centred" else (window, 0))
        dh = arr if arr is not given else np.empty_like(arr)
        _enhance_kernel(arr, dh, before, after)  # row-wise, safe in place
    else:
        dh = arr
    return dh, (float(dh.min()) if cfg.shift else 0.0)


def enhanced_matrix(D: np.ndarray, config: MatcherConfig | None = None, *,
                    enhance_window: int | None = None) -> np.ndarray:
    """The matrix the sequence search reads for `config` (module doc, 1): D contrast-enhanced
    (Eq. 5) and, with ``shift``, moved so that its minimum is 0; a new (Nq, Ndb) array in the
    config's dtype. `MatchResult.best_s` is the mean of this matrix over the best trajectory.
    `enhance_window`: the window of the ``dip`` rule (`window_of`)."""
    cfg = config or MatcherConfig()
    arr = _as_difference(D, _DTYPES[cfg.dtype])
    dh, shift = _enhanced(arr, cfg, D, window_of(cfg, enhance_window))
    if isinstance(D, np.ndarray) and np.may_share_memory(dh, D):
        dh = dh.copy()  # never the caller's array
    if shift:
        dh -= dh.dtype.type(shift)
    return dh


def match(
    D: np.ndarray,
    config: MatcherConfig | None = None,
    *,
    db_limit: np.ndarray | None = None,
    keep_S: bool = False,
    enhance_window: int | None = None,
) -> MatchResult:
    """Run the matcher described by `config` on the difference matrix D (Nq, Ndb).
    `enhance_window`: the window the ``dip`` rule chose for this database (`window_of`;
    `MatchResult.enhance_window` is the one used)."""
    cfg = config or MatcherConfig()
    window = window_of(cfg, enhance_window)
    ft = _DTYPES[cfg.dtype]
    arr = _as_difference(D, ft)
    nq, ndb = arr.shape
    limit = db_limits(db_limit, nq, ndb)
    dh, shift = _enhanced(arr, cfg, D, window)
    S_out = np.empty((nq, ndb) if keep_S else (0, 0), dtype=ft)
    found = search(dh, cfg, limit, 0, nq, 0, nq, keep_S=keep_S, S_out=S_out)
    S = None
    if keep_S:
        S_out -= ft(shift)
        S = S_out
    return finish(cfg, found, shift, ndb, window, S)


def db_limits(db_limit: np.ndarray | None, nq: int, ndb: int) -> np.ndarray:
    """`match`'s ``db_limit`` checked: (nq,) int64 in [0, ndb]; all of the database when None."""
    if db_limit is None:
        return np.full(nq, ndb, dtype=np.int64)
    limit = np.asarray(db_limit)
    if limit.shape != (nq,) or not np.issubdtype(limit.dtype, np.integer):
        raise DataError(f"db_limit must be an integer array of shape ({nq},), got "
                        f"{limit.dtype} {limit.shape}")
    if limit.size and (limit.min() < 0 or limit.max() > ndb):
        raise DataError(f"db_limit values must lie in [0, {ndb}]")
    return limit.astype(np.int64)


#: What the search kernel gives per query: (index, mean S of the best trajectory before the
#: shift, the same outside the ratio window, the velocity's index, trajectory points).
Found = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def search(dh: np.ndarray, cfg: MatcherConfig, limit: np.ndarray, q0: int, nqb: int, r0: int,
           nq: int, *, keep_S: bool = False, S_out: np.ndarray | None = None) -> Found:
    """The sequence search (module doc, 2-7) of queries q0 .. q0 + nqb - 1 of `nq` on the
    enhanced rows `dh` (row r of the whole matrix is ``dh[r - r0]``), before the shift."""
    offs = cfg.offsets()
    u_lo, _ = cfg.u_range()
    out = S_out if S_out is not None else np.empty((0, 0), dtype=dh.dtype)
    return _search_kernel(
        dh, offs, u_lo, cfg.edge_queries == "skip", cfg.out_of_range == "clip", limit,
        cfg.ratio_window // 2, keep_S, out, q0, nqb, r0, nq)


def finish(cfg: MatcherConfig, found: Found, shift: float, ndb: int, window: int,
           S: np.ndarray | None = None) -> MatchResult:
    """The `MatchResult` of the search's output for all queries and the matrix's shift (module
    doc, 1 and 6)."""
    index, best, second, vel_i, n_terms = found
    nq = len(index)
    best_s = best - shift  # +inf stays +inf
    second_s = second - shift
    found_q = index >= 0
    if cfg.score == "min":
        score = best_s.copy()
    elif cfg.score == "ratio":
        score = np.full(nq, np.inf)
        ok = found_q & np.isfinite(second_s) & (second_s > 0)
        score[found_q] = 1.0
        score[ok] = best_s[ok] / second_s[ok]
    else:
        score, capped = _inverse_score(best_s, n_terms, found_q)
        if cfg.capped_match is not None and capped.any():
            if cfg.capped_match >= ndb:
                raise ConfigError(f"capped_match={cfg.capped_match} is not a database frame "
                                  f"(the database has {ndb})")
            index[capped] = cfg.capped_match
    velocity = np.full(nq, np.nan)
    velocity[found_q] = cfg.velocities()[vel_i[found_q]]
    return MatchResult(
        index=index, score=score, best_s=best_s, velocity=velocity, n_terms=n_terms,
        complete=n_terms == cfg.ds + 1, config=cfg, S=S, enhance_window=window)


def _inverse_score(best_s: np.ndarray, n_terms: np.ndarray,
                   found: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """score="inverse" (module doc, 6): (-min(1 / S_sum, 1), +inf without a match; which
    queries were capped, i.e. 0 <= S_sum < 1)."""
    total = np.where(found, best_s * n_terms, np.inf)
    with np.errstate(divide="ignore"):
        inv = 1.0 / total
    capped = found & ((inv > 1.0) | (total == 0.0))
    score = np.full(len(total), np.inf)
    score[found] = -np.where(capped, 1.0, inv)[found]
    return score, capped


def seqslam(
    D: np.ndarray,
    *,
    ds: int = 10,
    v_min: float = 0.8,
    v_max: float = 1.1,
    v_step: float = 0.1,
    enhance_window: int = 10,
    db_limit: np.ndarray | None = None,
    keep_S: bool = False,
    **options: Any,
) -> MatchResult:
    """SeqSLAM on a difference matrix D (Nq queries x Ndb database, lower = more similar).

    Defaults are the paper's Table I. Other `MatcherConfig` fields (v_inclusive, enhance_mode,
    trajectory, edge_queries, out_of_range, score, ratio_window, dtype) are keyword options; see
    the module docstring for what each does and which source it follows.
    """
    try:
        cfg = MatcherConfig(method="seqslam", ds=ds, v_min=v_min, v_max=v_max, v_step=v_step,
                            enhance_window=enhance_window, **options)
    except TypeError as exc:
        raise ConfigError(f"seqslam: {exc}") from None
    return match(D, cfg, db_limit=db_limit, keep_S=keep_S)


def single_frame(
    D: np.ndarray,
    *,
    score: ScoreKind = "min",
    ratio_window: int = 10,
    enhance_window: int = 0,
    db_limit: np.ndarray | None = None,
    keep_S: bool = False,
    **options: Any,
) -> MatchResult:
    """No-sequence baseline: per query the database frame with the lowest difference.

    Same interface and result as `seqslam` (ds = 0, one velocity); by default no enhancement, so
    the score is the raw difference minus the matrix minimum.
    """
    try:
        cfg = MatcherConfig(method="single_frame", ds=0, score=score, ratio_window=ratio_window,
                            enhance_window=enhance_window, **options)
    except TypeError as exc:
        raise ConfigError(f"single_frame: {exc}") from None
    return match(D, cfg, db_limit=db_limit, keep_S=keep_S)
