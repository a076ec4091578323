"""Loop-closure metrics on scikit-learn: PR curve, ROC AUC, recall at 100 % precision, F1 max,
extended precision.

Orientation: the matcher's score is LOWER = better; every metric here takes a CONFIDENCE, HIGHER =
more confident. `confidence_from_score` is the one place the sign is flipped (a score of +inf,
"no match", becomes -inf, "never accepted").

Each query contributes one reported match. At a threshold tau the accepted matches are those with
confidence >= tau; an accepted correct match is a TP, an accepted wrong one a FP, and

    precision = TP / (TP + FP)        recall = TP / (number of queries that have a true place)

so a query whose match is wrong (or that claims no match) but has a true place lowers recall at
every threshold. The caller states, per query, whether the reported match is correct, whether the
query has any true place, and whether it takes part at all (`valid`), e.g. with the label helpers:

* `paper_labels` (paper protocol, §IV.A): correct = matched database frame within D_thresh = 10 m
  of the query's ground-truth position; has a true place = some database frame within D_thresh.
* `revisit_labels` (revisit protocol): correct = within 3 m; wrong = beyond 20 m; a match in the
  3-20 m band is left out of the evaluation entirely (valid = False; it counts neither as TP, FP nor
  in the recall denominator); queries with no eligible database frame within 3 m are the negatives.

ROC: the binary classification "is the reported match correct" by confidence over the valid
queries (queries that claim no match rank below all others), TPR = TP / correct,
FPR = FP / wrong, area by `roc_auc_score`.
Recall at 100 % precision is exact (no false positive accepted); the authors' code used >= 99 %,
available as `precision_level=0.99`. Extended precision (Yin et al.) is
EP = (P_R0 + R_P100) / 2 with P_R0 the precision at the lowest recall (the most confident
threshold) and R_P100 the exact recall at 100 % precision.

Degenerate cases: empty input, NaN or +inf confidences, mismatched lengths, or no query with a
true place (recall undefined) raise DataError. No correct match at all gives recall 0, F1 0,
R_P100 0, P_R0 0 and `roc_auc = None` (one class only; said in `notes`); all-equal confidences
give a one-threshold curve.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree
from sklearn.metrics import precision_recall_curve, roc_auc_score, roc_curve

from .errors import ConfigError, DataError


def confidence_from_score(score: np.ndarray) -> np.ndarray:
    """Matcher score (lower = better, +inf = no match) -> confidence (higher = better)."""
    return -np.asarray(score, dtype=np.float64)


def _clean(values: np.ndarray) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in np.asarray(values, dtype=np.float64)]


@dataclass
class Labels:
    """Per-query ground truth for `evaluate` (see the module docstring)."""

    is_correct: np.ndarray  # bool (N,)
    has_true_place: np.ndarray  # bool (N,)
    valid: np.ndarray  # bool (N,)
    match_distance: np.ndarray  # float (N,), metres, +inf where no match


@dataclass
class Metrics:
    """Curves and scalar metrics of one evaluation; `to_dict` gives JSON."""

    n_queries: int
    n_valid: int
    n_positive: int  # valid queries with a true place (recall denominator)
    n_correct: int  # valid queries whose reported match is correct
    n_claimed: int  # valid queries with a finite confidence
    precision: np.ndarray  # PR curve, thresholds increasing; last point (1, 0) has no threshold
    recall: np.ndarray
    thresholds: np.ndarray
    fpr: np.ndarray
    tpr: np.ndarray
    roc_thresholds: np.ndarray
    roc_auc: float | None
    recall_at_100: float  # exact: no false positive
    precision_level: float
    recall_at_precision: float  # at precision >= precision_level
    precision_at_min_recall: float  # P_R0
    extended_precision: float
    f1_max: float
    notes: list[str] = field(default_factory=list)
    #: fraction of queries with a true place whose reported match is one (None: no such query)
    recall_at_1: float | None = None
    #: {N: fraction with a true place among the N nearest database frames} (`retrieval_recall`)
    recall_at_n: dict[int, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, value in self.__dict__.items():
            out[name] = _clean(value) if isinstance(value, np.ndarray) else value
        return out


def _bool_array(x: Any, name: str, n: int) -> np.ndarray:
    arr = np.asarray(x)
    if arr.shape != (n,):
        raise DataError(f"{name} must have shape ({n},) like confidence, got {arr.shape}")
    if arr.dtype != bool:
        if not np.issubdtype(arr.dtype, np.integer) or not np.isin(arr, (0, 1)).all():
            raise DataError(f"{name} must be boolean, got dtype {arr.dtype}")
        arr = arr.astype(bool)
    return arr


def evaluate(
    confidence: np.ndarray,
    is_correct: np.ndarray,
    has_true_place: np.ndarray,
    *,
    valid: np.ndarray | None = None,
    precision_level: float = 1.0,
) -> Metrics:
    """All metrics for one run. Arrays are per query; `confidence` higher = more confident,
    -inf = no match claimed. See the module docstring for the definitions."""
    conf = np.asarray(confidence, dtype=np.float64) if np.ndim(confidence) else np.array([])
    if conf.ndim != 1:
        raise DataError(f"confidence must be 1-D (one value per query), got shape {conf.shape}")
    n = conf.shape[0]
    if n == 0:
        raise DataError("nothing to evaluate: no queries")
    if np.isnan(conf).any():
        raise DataError(f"confidence has {int(np.isnan(conf).sum())} NaN values")
    if np.isposinf(conf).any():
        raise DataError("confidence has +inf values (a score of -inf?)")
    if not 0.0 < precision_level <= 1.0:
        raise ConfigError(f"precision_level must be in (0, 1], got {precision_level}")
    correct = _bool_array(is_correct, "is_correct", n)
    has_true = _bool_array(has_true_place, "has_true_place", n)
    ok = np.ones(n, bool) if valid is None else _bool_array(valid, "valid", n)
    if (correct & ~has_true).any():
        raise DataError("a query is marked correct but has no true place")
    notes: list[str] = []

    correct_all, has_true_all = correct & np.isfinite(conf), has_true
    conf, correct, has_true = conf[ok], correct[ok], has_true[ok]
    n_valid = int(ok.sum())
    n_pos = int(has_true.sum())
    if n_pos == 0:
        raise DataError(f"no (valid) query has a true place among {n} queries: recall is undefined")
    claimed = np.isfinite(conf)
    y, s = correct[claimed], conf[claimed]
    n_correct = int(y.sum())

    if n_correct == 0:
        notes.append("no correct match: recall, F1 and R_P100 are 0")
        thr = np.unique(s)
        precision = np.append(np.zeros(thr.size), 1.0)
        recall = np.zeros(thr.size + 1)
    else:
        precision, recall_sk, thr = precision_recall_curve(y, s)
        recall = recall_sk * (n_correct / n_pos)

    # points with a threshold (drop sklearn's appended (1, 0) end point)
    p, r = precision[:-1], recall[:-1]
    exact = p == 1.0  # tp / (tp + fp) is exactly 1.0 iff fp == 0
    recall_at_100 = float(r[exact].max()) if exact.any() else 0.0
    at_level = p >= precision_level if precision_level < 1.0 else exact
    recall_at_level = float(r[at_level].max()) if at_level.any() else 0.0
    with np.errstate(invalid="ignore", divide="ignore"):
        f1 = np.where(p + r > 0, 2 * p * r / (p + r), 0.0)
    f1_max = float(f1.max()) if f1.size else 0.0
    p_r0 = float(p[-1]) if p.size else 0.0
    if s.size == 0:
        notes.append("no query claimed a match")

    # ROC over all valid queries; unclaimed ones rank below every claimed one
    roc_conf = conf.copy()
    if (~claimed).any():
        roc_conf[~claimed] = (s.min() - 1.0) if s.size else 0.0
    if correct.all() or not correct.any():
        notes.append("ROC AUC undefined: all valid matches are " +
                     ("correct" if correct.all() else "wrong"))
        roc_auc = None
        fpr = tpr = roc_thr = np.array([])
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fpr, tpr, roc_thr = roc_curve(correct, roc_conf)
            roc_auc = float(roc_auc_score(correct, roc_conf))

    # Recall@1: every query with a true place, valid or not (a match in the excluded band is no
    # true place), as the retrieval literature counts it
    n_true = int(has_true_all.sum())
    recall_at_1 = float((correct_all & has_true_all).sum() / n_true) if n_true else None
    return Metrics(
        recall_at_1=recall_at_1,
        n_queries=n, n_valid=n_valid, n_positive=n_pos, n_correct=int(correct.sum()),
        n_claimed=int(claimed.sum()), precision=precision, recall=recall, thresholds=thr,
        fpr=fpr, tpr=tpr, roc_thresholds=roc_thr, roc_auc=roc_auc,
        recall_at_100=recall_at_100, precision_level=float(precision_level),
        recall_at_precision=recall_at_level, precision_at_min_recall=p_r0,
        extended_precision=(p_r0 + recall_at_100) / 2, f1_max=f1_max, notes=notes)


def retrieval_recall(D: np.ndarray, has_true_place: np.ndarray, is_true: Any,
                     ns: tuple[int, ...] = (1, 5, 10), db_limit: np.ndarray | None = None) -> dict[int, float]:
    """Recall@N, the field's retrieval metric: the fraction of queries with a true place that
    have one among the N database frames nearest in descriptor distance (`D`, (Nq, Ndb), lower =
    nearer), each query ranking only the frames it may match (j < db_limit[i]).
    `is_true(queries, matches)` says elementwise whether a database frame is a true place.
    Empty when no query has a true place."""
    D = np.asarray(D, dtype=np.float64)
    ndb = D.shape[1]
    queries = np.flatnonzero(np.asarray(has_true_place, dtype=bool))
    if not len(queries) or not ndb:
        return {}
    if db_limit is not None:
        D = np.where(np.arange(ndb)[None, :] < np.asarray(db_limit)[:, None], D, np.inf)
    k = min(max(ns), ndb)
    sub = D[queries]
    top = np.argpartition(sub, k - 1, axis=1)[:, :k] if k < ndb else np.tile(np.arange(ndb), (len(queries), 1))
    order = np.take_along_axis(sub, top, axis=1).argsort(axis=1, kind="stable")
    top = np.take_along_axis(top, order, axis=1)
    ranked = np.take_along_axis(sub, top, axis=1)
    hit = np.asarray(is_true(np.repeat(queries, k).reshape(-1, k), top), dtype=bool) & np.isfinite(ranked)
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), k)
    return {n: float((first < n).mean()) for n in ns}


# --------------------------------------------------------------------------- labels


def _xy(a: Any, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
        raise DataError(f"{name} must be an (N, 2) array of ground-plane positions, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise DataError(f"{name} has NaN or infinite positions")
    return arr


def _match_distance(q: np.ndarray, db: np.ndarray, index: Any) -> np.ndarray:
    idx = np.asarray(index)
    if idx.shape != (q.shape[0],) or not np.issubdtype(idx.dtype, np.integer):
        raise DataError(f"index must be an integer array of shape ({q.shape[0]},), got "
                        f"{idx.dtype} {idx.shape}")
    if (idx >= db.shape[0]).any() or (idx < -1).any():
        raise DataError(f"index values must be -1 (no match) or in [0, {db.shape[0]})")
    dist = np.full(q.shape[0], np.inf)
    found = idx >= 0
    dist[found] = np.linalg.norm(q[found] - db[idx[found]], axis=1)
    return dist


def paper_labels(query_xy: Any, db_xy: Any, index: Any, *, d_thresh: float = 10.0) -> Labels:
    """Paper protocol: correct within `d_thresh` metres; every query with a database frame
    within `d_thresh` has a true place; all queries valid."""
    if d_thresh <= 0:
        raise ConfigError(f"d_thresh must be > 0, got {d_thresh}")
    q, db = _xy(query_xy, "query_xy"), _xy(db_xy, "db_xy")
    dist = _match_distance(q, db, index)
    nearest, _ = cKDTree(db).query(q)
    return Labels(is_correct=dist <= d_thresh, has_true_place=nearest <= d_thresh,
                  valid=np.ones(q.shape[0], bool), match_distance=dist)


def revisit_labels(
    query_xy: Any,
    db_xy: Any,
    index: Any,
    *,
    db_limit: Any = None,
    tp_dist: float = 3.0,
    fp_dist: float = 20.0,
) -> Labels:
    """Revisit protocol: correct within `tp_dist`, wrong beyond `fp_dist`, in between left out.

    A query has a true place if an ELIGIBLE database frame (``j < db_limit[i]``, all when None)
    lies within `tp_dist`.
    """
    if not 0 < tp_dist <= fp_dist:
        raise ConfigError(f"need 0 < tp_dist <= fp_dist, got {tp_dist}, {fp_dist}")
    q, db = _xy(query_xy, "query_xy"), _xy(db_xy, "db_xy")
    dist = _match_distance(q, db, index)
    limit = np.full(q.shape[0], db.shape[0]) if db_limit is None else np.asarray(db_limit)
    if limit.shape != (q.shape[0],):
        raise DataError(f"db_limit must have shape ({q.shape[0]},), got {limit.shape}")
    near = cKDTree(db).query_ball_point(q, r=tp_dist)
    has_true = np.array([bool(js) and min(js) < lim for js, lim in zip(near, limit, strict=True)])
    correct = dist <= tp_dist
    valid = correct | (dist > fp_dist)
    return Labels(is_correct=correct, has_true_place=has_true, valid=valid, match_distance=dist)


def evaluate_labels(confidence: np.ndarray, labels: Labels, *,
                    precision_level: float = 1.0) -> Metrics:
    """`evaluate` with the arrays of a `Labels`."""
    return evaluate(confidence, labels.is_correct, labels.has_true_place, valid=labels.valid,
                    precision_level=precision_level)
