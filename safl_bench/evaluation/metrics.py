"""Loop-closure metrics: every measure defined once, by name (metrics version 3).

Orientation: the matcher's score is LOWER = better; every measure here reads a CONFIDENCE, HIGHER
= more confident. `confidence_from_score` is the one place the sign is flipped (a score of +inf,
"no match", becomes -inf, "never accepted").

What the measures read (`Outcomes`, one entry per scored query; the label layer that fills it
is `safl_bench.evaluation.cell.score_matches` on `safl_bench.evaluation.groundtruth.GroundTruth`):

Which queries are scored: those the task scores (all but its first ``context_queries``, the
context of the paper and BEVPlace tasks' sequence matcher, `safl_bench.tasks.spec.TaskSpec`), less
those an evaluation setting leaves out (``max_frames``, ``trim_queries``;
`safl_bench.evaluation.cell.scored_queries`); the same queries for every method and both
matching modes of a task. A scored query that a setting leaves UNANSWERED (the matcher reports
no match: ``edge_queries="skip"`` with a longer ``ds`` or a centred trajectory, a revisit query
whose trajectory has no candidate) stays in every measure as a query that reported none: it
lowers recall over positives if it has a true place and ranks below every answer in the AUC.

* ``has_candidate``: the query may match at least one database frame (revisit protocol: some
  frame is older than the time window; paper and BEVPlace protocols: always). A query without a
  candidate cannot be answered and is left out of EVERY measure (LoGG3D-Net skips such queries
  the same way, ``evaluation/eval_sequence.py`` line 117).
* ``has_true_place``: some candidate lies within the true-positive radius. Fixed by the ground
  truth alone: the POSITIVES, ``P`` = their number, are the same for every method on a task.
* ``confidence``: of the query's one reported match; -inf = the matcher reported none.
* ``label`` of the reported match: correct (+1: a candidate within the true-positive radius),
  wrong (-1: beyond the false-positive radius, or not a candidate), or ambiguous (0: the revisit
  protocol's 3-20 m band). ``C`` = the number of correct reported matches.
* ``true_rank`` (single-frame mode): the rank of the nearest true place among the query's
  candidates by descriptor distance (1 = nearest; 0 = no true place). See "Ties" below.

Thresholds. At a threshold tau the ACCEPTED matches are those with confidence >= tau (tied
confidences are accepted together: one threshold per distinct confidence, scikit-learn's
``precision_recall_curve``). TP(tau) = accepted correct, FP(tau) = accepted wrong; an accepted
ambiguous match is neither, as in LoGG3D-Net's KITTI revisit evaluation (``eval_sequence.py``
lines 169-174 at commit ``cfbe064``: within ``revisit_criteria`` a TP, beyond
``not_revisit_criteria`` a FP, nothing in between). Precision(tau) = TP / (TP + FP).

Two recall conventions exist in the field, and both are computed, named apart:

* recall OVER POSITIVES, ``R(tau) = TP(tau) / P``: the measures without a suffix. A query with a
  true place whose match is wrong, ambiguous, or rejected, or that reported none, lowers it, so
  a method cannot raise it by answering less.
* recall OVER CORRECT MATCHES, ``Rc(tau) = TP(tau) / C``: the measures ending in ``_of_correct``.
  This is the paper's Eq. 13 (TP / (TP + FN), FN = correct matches "erroneously discarded by the
  match score") as its authors' scoring computes it (``precision_recall_curve(is_correct,
  score)`` in ``src/plot/SLFL/plotDraw_slfl.py`` lines 111-128 at commit ``25be0fd``) and as
  VPR-Bench does (``performance_comparison.py`` line 23 at commit ``77ad30f``). It is 1 at the
  lowest threshold whatever the share of wrong matches. ``Rc = R * P / C``.

LoGG3D-Net's recall (``eval_sequence.py`` lines 176-180, 197) is neither: its TP + FN drops the
positive queries whose accepted match was wrong or ambiguous at that threshold, so it moves with
the method's wrong answers; ours keeps P fixed (their precision equals ours at every threshold).

The measures (each a fraction in [0, 1]; in a record's ``metrics``):

| name | definition | denominator |
|---|---|---|
| ``recall_at_100_precision`` | max R(tau) over the thresholds with FP(tau) = 0 (0 when the most confident match is wrong) | P |
| ``recall_at_100_precision_of_correct`` | the same in Rc | C |
| ``recall_at_precision[_of_correct]`` (`evaluate` only) | max R (Rc) over the thresholds with precision >= ``precision_level`` (the authors' 0.99) | P (C) |
| ``authors_recall_at_99p`` | the authors' reading: Rc at the FIRST point of the PR curve (thresholds increasing) whose precision is >= 0.99 (``AUTHORS_PRECISION``), ``recall[[x for x in range(len(precision)) if precision[x] >= 0.99][0]]`` of ``precision_recall_curve(is_correct, 1/S)`` (src/plot/plotPaper2.py lines 59-60, the curve of src/plot/SLFL/plotDraw_slfl.py line 128, at commit ``25be0fd``); recall only falls along the curve, so this is the largest Rc with precision >= 0.99 | C |
| ``f1_max`` | max over tau of 2 Pr R / (Pr + R) | P |
| ``f1_max_of_correct`` | the same with Rc | C |
| ``extended_precision`` | (P_R0 + R_P100) / 2 (Ferrarini et al.): P_R0 = precision at the most confident threshold, R_P100 = ``recall_at_100_precision`` | P |
| ``extended_precision_of_correct`` | the same with Rc: VPR-Bench's ``compute_extendedprecision`` (lines 105-113) | C |
| ``auc`` | ROC AUC of "is the reported match correct" by confidence (``roc_auc_score``): positives = correct matches, negatives = wrong matches and queries that reported none (ranked below all others); the paper's Eq. 14; None with one class only | queries with a candidate, less ambiguous matches |
| ``recall_at_1`` | correct reported matches / P (= R at the lowest threshold: accept everything) | P |
| ``recall_at_n`` {"N"} | queries with ``1 <= true_rank <= N`` / P (single-frame mode only) | P |

Ties (one rule everywhere). Equal distances are ordered by the LOWER database index, in the
matcher's precision (``MatcherConfig.dtype``, float32 by default): the matcher keeps the first
minimum (`safl_bench.matching.matcher`), and `true_place_ranks` counts a candidate as nearer than the
true place when its distance is lower, or equal with a lower index, after converting the matrix
to the same dtype. So ``recall_at_n["1"]`` equals the single-frame ``recall_at_1`` by
construction. Tied confidences across queries are one threshold (above).

Degenerate cases. Empty input, NaN or +inf confidences, mismatched lengths, a correct match on a
query without a true place, or no positive at all (`NoPositivesError`: recall is undefined; the
runner names the task) raise DataError. No correct match gives 0 for every recall, F1 and
extended precision (said in ``notes``); one class only gives ``auc = None``.

``authors_recall_at_99p`` differs from ``recall_at_100_precision`` in two ways at once: one
wrong match in a hundred accepted is allowed, and the recall is over the correct matches (a
method that answers a query wrongly loses nothing by it). Named apart so that nobody reads one
for the other; tables show both.

Abstaining. A method may report no match for a query (a retrieval method whose verification
rejects every candidate: MapClosures answers about one query in six on KITTI 00's revisit task).
The recalls and F1 above count such a query with a true place against it (denominator P), so
answering less never raises them. ``auc`` does not: it asks whether the method's confidence
separates its correct answers from everything else, and a method that answers only where it is
sure, and is always right there, separates them perfectly (AUC 1 at a recall of 16 %). That is
the selective-prediction view, where a measure of how well answers are ranked is read beside
the COVERAGE, never alone (Geifman and El-Yaniv, "Selective classification for deep neural
networks", NeurIPS 2017, risk-coverage curves; El-Yaniv and Wiener, JMLR 2010). So the measures
keep their definitions (no version change: every stored value stays what it was) and
`answered_share` gives the coverage: of the scored queries with a true place, the share for
which the method reported a match. The leaderboard never marks a cell best or tied
(`safl_bench.leaderboard.tables.ANSWERED_MIN`) whose method answered fewer than half of them,
and its notes say which rows and why.

``METRICS_VERSION`` is stored in every record: version 1 (records without it) divided recall by
the queries with a true place whose match was not ambiguous (so P depended on the method) and
counted queries without a candidate in the AUC; it had no ``_of_correct`` measures. Version 2
had no ``authors_recall_at_99p``; everything else is version 3's (a version-2 record holds its
per-query outcomes, so `safl_bench.results.records.rescore` adds it).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sklearn.metrics import precision_recall_curve, roc_auc_score, roc_curve

from safl_bench.errors import ConfigError, DataError
from safl_bench.matching.confidence import confidence_from_score  # noqa: F401  (re-exported)

#: The version of these definitions; records store it (`safl_bench.results.records`).
METRICS_VERSION = 3

#: The precision at which the paper's authors read their recall (``authors_recall_at_99p``).
AUTHORS_PRECISION = 0.99

#: The N of the Recall@N that single-frame results report.
RECALL_AT = (1, 5, 10)

#: Labels of a reported match in `Outcomes.label`.
CORRECT, AMBIGUOUS, WRONG = 1, 0, -1


class NoPositivesError(DataError):
    """No query has a true place: every recall is undefined."""


def _clean(values: np.ndarray) -> list[float | None]:
    return [float(v) if np.isfinite(v) else None for v in np.asarray(values, dtype=np.float64)]


@dataclass(frozen=True)
class Outcomes:
    """Per query, everything the measures read (module docstring); arrays of one length.

    Records store these, so a record's measures can be recomputed without the data."""

    confidence: np.ndarray  # float64, -inf = no match reported
    label: np.ndarray  # int8, CORRECT / AMBIGUOUS / WRONG (read only where a match was reported)
    has_true_place: np.ndarray  # bool
    has_candidate: np.ndarray  # bool
    true_rank: np.ndarray | None = None  # int64, 1-based rank of the nearest true place; 0 = none
    #: int64, the database frame each query matched (-1 = no match reported); read by the
    #: loop-closure stage (`safl_bench.slam`), never by a measure; None in older records
    match: np.ndarray | None = None
    #: float64 (n, 3): the method's own estimate of the pose of its matched database frame in
    #: the query's frame, [x m, y m, yaw rad] (T_query^-1 T_match in SE(2)); a row of NaN where
    #: it gives none or reported no match; None (the whole field) for methods that estimate no
    #: pose (every descriptor method). Read by `safl_bench.slam`, never by a measure.
    relative_pose: np.ndarray | None = None


@dataclass
class Metrics:
    """Curves and measures of one evaluation (module docstring); `to_dict` gives JSON."""

    n_queries: int  # all queries given
    n_scored: int  # queries with a candidate: the ones every measure reads
    n_positive: int  # P: queries with a true place
    n_correct: int  # C: correct reported matches
    n_ambiguous: int  # reported matches in the ambiguous band
    n_claimed: int  # scored queries that reported a match
    precision: np.ndarray  # PR curve, thresholds increasing; last point (1, 0) has no threshold
    recall: np.ndarray  # over positives
    recall_of_correct: np.ndarray  # over correct matches
    thresholds: np.ndarray
    fpr: np.ndarray
    tpr: np.ndarray
    roc_thresholds: np.ndarray
    roc_auc: float | None
    recall_at_100: float
    recall_at_100_of_correct: float
    precision_level: float
    recall_at_precision: float
    recall_at_precision_of_correct: float
    authors_recall_at_99p: float  # Rc at the first point with precision >= 0.99 (the authors')
    precision_at_min_recall: float  # P_R0
    extended_precision: float
    extended_precision_of_correct: float
    f1_max: float
    f1_max_of_correct: float
    recall_at_1: float
    #: {N: share of positives with a true place among the N nearest candidates} (`recall_at_n`)
    recall_at_n: dict[int, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

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


def _confidence(confidence: Any) -> np.ndarray:
    conf = np.asarray(confidence, dtype=np.float64) if np.ndim(confidence) else np.array([])
    if conf.ndim != 1:
        raise DataError(f"confidence must be 1-D (one value per query), got shape {conf.shape}")
    if conf.shape[0] == 0:
        raise DataError("nothing to evaluate: no queries")
    if np.isnan(conf).any():
        raise DataError(f"confidence has {int(np.isnan(conf).sum())} NaN values")
    if np.isposinf(conf).any():
        raise DataError("confidence has +inf values (a score of -inf?)")
    return conf


def outcomes(
    confidence: Any,
    is_correct: Any,
    has_true_place: Any,
    *,
    ambiguous: Any = None,
    has_candidate: Any = None,
    true_rank: Any = None,
    match: Any = None,
    relative_pose: Any = None,
) -> Outcomes:
    """Validated `Outcomes` from per-query arrays: `is_correct` (the reported match is a true
    place), `ambiguous` (it lies in the band: neither correct nor wrong; None = none does),
    `has_candidate` (None = every query has one), `true_rank` (optional), `match` (optional:
    the matched database frame, -1 = none), `relative_pose` (optional: (n, 3) [x, y, yaw] of
    the matched frame in the query's frame, NaN rows = none)."""
    conf = _confidence(confidence)
    n = conf.shape[0]
    correct = _bool_array(is_correct, "is_correct", n)
    has_true = _bool_array(has_true_place, "has_true_place", n)
    band = np.zeros(n, bool) if ambiguous is None else _bool_array(ambiguous, "ambiguous", n)
    cand = np.ones(n, bool) if has_candidate is None else _bool_array(has_candidate, "has_candidate", n)
    if (correct & band).any():
        raise DataError("a reported match is marked both correct and ambiguous")
    if (correct & ~has_true).any():
        raise DataError("a query is marked correct but has no true place")
    if (has_true & ~cand).any():
        raise DataError("a query has a true place but no candidate")
    label = np.where(correct, CORRECT, np.where(band, AMBIGUOUS, WRONG)).astype(np.int8)
    rank = None
    if true_rank is not None:
        rank = np.asarray(true_rank)
        if rank.shape != (n,) or not np.issubdtype(rank.dtype, np.integer) or (rank < 0).any():
            raise DataError(f"true_rank must be integers >= 0 of shape ({n},), got "
                            f"{rank.dtype} {rank.shape}")
        if ((rank > 0) != has_true).any():
            raise DataError("true_rank must be >= 1 exactly where a query has a true place")
        rank = rank.astype(np.int64)
    matched = None
    if match is not None:
        matched = np.asarray(match)
        if (matched.shape != (n,) or not np.issubdtype(matched.dtype, np.integer)
                or (matched < -1).any()):
            raise DataError(f"match must be integers >= -1 of shape ({n},), got "
                            f"{matched.dtype} {matched.shape}")
        matched = matched.astype(np.int64)
    pose = None
    if relative_pose is not None:
        pose = np.asarray(relative_pose, dtype=np.float64)
        if pose.shape != (n, 3):
            raise DataError(f"relative_pose must have shape ({n}, 3), got {pose.shape}")
        if np.isinf(pose).any() or (np.isnan(pose).any(axis=1) != np.isnan(pose).all(axis=1)).any():
            raise DataError("relative_pose rows must be finite [x, y, yaw] or all NaN (none)")
    return Outcomes(confidence=conf, label=label, has_true_place=has_true, has_candidate=cand,
                    true_rank=rank, match=matched, relative_pose=pose)


def evaluate(
    confidence: Any,
    is_correct: Any,
    has_true_place: Any,
    *,
    ambiguous: Any = None,
    has_candidate: Any = None,
    precision_level: float = 1.0,
) -> Metrics:
    """Every measure of one run from per-query arrays (`outcomes` says what each means);
    `confidence` higher = more confident, -inf = no match reported."""
    return evaluate_outcomes(
        outcomes(confidence, is_correct, has_true_place, ambiguous=ambiguous,
                 has_candidate=has_candidate),
        precision_level=precision_level)


def _best_recall(recall: np.ndarray, keep: np.ndarray) -> float:
    return float(recall[keep].max()) if keep.any() else 0.0


def _authors_recall(precision: np.ndarray, recall_of_correct: np.ndarray) -> float:
    """The authors' reading of the PR curve (``authors_recall_at_99p``): the recall over
    correct matches at its first point (thresholds increasing, the final (1, 0) included) with
    precision >= ``AUTHORS_PRECISION``."""
    first = int(np.flatnonzero(precision >= AUTHORS_PRECISION)[0])
    return float(recall_of_correct[first])


def _f1(p: np.ndarray, r: np.ndarray) -> float:
    with np.errstate(invalid="ignore", divide="ignore"):
        f1 = np.where(p + r > 0, 2 * p * r / (p + r), 0.0)
    return float(f1.max()) if f1.size else 0.0


def evaluate_outcomes(
    o: Outcomes,
    *,
    precision_level: float = 1.0,
    recall_at: Sequence[int] = (),
) -> Metrics:
    """Every measure from `Outcomes` (module docstring); Recall@N for each N of `recall_at`
    when the outcomes carry ranks."""
    if not 0.0 < precision_level <= 1.0:
        raise ConfigError(f"precision_level must be in (0, 1], got {precision_level}")
    n = len(o.confidence)
    notes: list[str] = []
    scored = o.has_candidate
    conf, label, has_true = o.confidence[scored], o.label[scored], o.has_true_place[scored]
    n_pos = int(has_true.sum())
    if n_pos == 0:
        raise NoPositivesError(f"no query has a true place among {n} queries "
                               f"({int(scored.sum())} with a candidate): recall is undefined")
    claimed = np.isfinite(conf)
    correct = claimed & (label == CORRECT)
    ambiguous = claimed & (label == AMBIGUOUS)
    decided = claimed & ~ambiguous  # accepted, these are TP or FP
    y, s = correct[decided], conf[decided]
    n_correct = int(correct.sum())

    if n_correct == 0:
        notes.append("no correct match: every recall, F1 and extended precision is 0")
        thr = np.unique(s)
        precision = np.append(np.zeros(thr.size), 1.0)
        recall_c = np.zeros(thr.size + 1)
    else:
        precision, recall_c, thr = precision_recall_curve(y, s)
    recall = recall_c * (n_correct / n_pos)

    # the points that have a threshold (sklearn appends (1, 0) without one)
    p, r, rc = precision[:-1], recall[:-1], recall_c[:-1]
    exact = p == 1.0  # TP / (TP + FP) is exactly 1.0 iff FP == 0
    at_level = p >= precision_level if precision_level < 1.0 else exact
    p_r0 = float(p[-1]) if p.size else 0.0
    if s.size == 0:
        notes.append("no query reported a match outside the ambiguous band")

    # ROC over the scored queries less the ambiguous matches; no match ranks below every match
    roc_keep = ~ambiguous
    roc_y = correct[roc_keep]
    roc_conf = conf[roc_keep].copy()
    unclaimed = ~np.isfinite(roc_conf)
    if unclaimed.any():
        roc_conf[unclaimed] = (roc_conf[~unclaimed].min() - 1.0) if (~unclaimed).any() else 0.0
    if roc_y.all() or not roc_y.any():
        notes.append("ROC AUC undefined: every match it reads is " +
                     ("correct" if roc_y.all() else "wrong"))
        roc_auc = None
        fpr = tpr = roc_thr = np.array([])
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fpr, tpr, roc_thr = roc_curve(roc_y, roc_conf)
            roc_auc = float(roc_auc_score(roc_y, roc_conf))

    r100, rc100 = _best_recall(r, exact), _best_recall(rc, exact)
    ranks = None if o.true_rank is None else o.true_rank[scored]
    return Metrics(
        n_queries=n, n_scored=int(scored.sum()), n_positive=n_pos, n_correct=n_correct,
        n_ambiguous=int(ambiguous.sum()), n_claimed=int(claimed.sum()),
        precision=precision, recall=recall, recall_of_correct=recall_c, thresholds=thr,
        fpr=fpr, tpr=tpr, roc_thresholds=roc_thr, roc_auc=roc_auc,
        recall_at_100=r100, recall_at_100_of_correct=rc100,
        precision_level=float(precision_level),
        recall_at_precision=_best_recall(r, at_level),
        recall_at_precision_of_correct=_best_recall(rc, at_level),
        authors_recall_at_99p=_authors_recall(precision, recall_c),
        precision_at_min_recall=p_r0,
        extended_precision=(p_r0 + r100) / 2, extended_precision_of_correct=(p_r0 + rc100) / 2,
        f1_max=_f1(p, r), f1_max_of_correct=_f1(p, rc),
        recall_at_1=n_correct / n_pos,
        recall_at_n=({} if ranks is None or not recall_at else
                     recall_at_n(ranks, has_true, recall_at)),
        notes=notes)


# --------------------------------------------------------------------------- retrieval ranks


def answered_share(outcomes: Outcomes) -> float | None:
    """Coverage (module docstring, "Abstaining"): of the scored queries with a true place, the
    share that reported a match (right or wrong); None when there is no such query."""
    positives = np.asarray(outcomes.has_true_place, bool) & np.asarray(outcomes.has_candidate, bool)
    if not positives.any():
        return None
    answered = np.asarray(outcomes.confidence, np.float64) > -np.inf  # -inf: reported none
    return float(answered[positives].mean())


def true_place_ranks(
    D: np.ndarray,
    true_places: Sequence[np.ndarray],
    *,
    db_limit: np.ndarray | None = None,
    dtype: str = "float32",
) -> np.ndarray:
    """(Nq,) int64: per query, the 1-based rank of its nearest true place among its candidates
    (database frames ``j < db_limit[i]``, all when None) by the distances `D` (Nq, Ndb; lower =
    nearer), 0 for a query without a true place. `true_places[i]`: the database indices that
    are a true place of query i (all of them candidates).

    The tie rule of the matcher (module docstring): `D` is converted to `dtype` first, and a
    candidate counts as nearer when its distance is lower, or equal with a lower index."""
    if dtype not in ("float32", "float64"):
        raise ConfigError(f"dtype must be 'float32' or 'float64', got {dtype!r}")
    Dm = np.ascontiguousarray(D, dtype=np.dtype(dtype))
    if Dm.ndim != 2 or len(true_places) != Dm.shape[0]:
        raise DataError(f"need an (Nq, Ndb) matrix and one index array per query, got "
                        f"{Dm.shape} and {len(true_places)}")
    nq, ndb = Dm.shape
    limit = np.full(nq, ndb, np.int64) if db_limit is None else np.asarray(db_limit, np.int64)
    best = np.zeros(nq, Dm.dtype)
    jbest = np.full(nq, -1, np.int64)  # -1: no true place
    for i, js in enumerate(true_places):
        js = np.asarray(js, dtype=np.int64)
        if js.size == 0:
            continue
        if js.min() < 0 or js.max() >= limit[i]:
            raise DataError(f"query {i}: a true place {js.max()} is not a candidate "
                            f"(candidates: j < {limit[i]})")
        vals = Dm[i, js]
        k = int(np.argmin(vals))  # first minimum; `js` is sorted, so the lowest index
        best[i], jbest[i] = vals[k], js[k]
    ranks = np.zeros(nq, np.int64)
    cols = np.arange(ndb)
    rows = np.flatnonzero(jbest >= 0)
    for start in range(0, rows.size, 256):  # row blocks: a few MB at a time
        r = rows[start:start + 256]
        b, jb = best[r, None], jbest[r, None]
        nearer = (Dm[r] < b) | ((Dm[r] == b) & (cols < jb))
        nearer &= cols < limit[r, None]
        ranks[r] = np.count_nonzero(nearer, axis=1) + 1
    return ranks


def recall_at_n(ranks: np.ndarray, has_true_place: np.ndarray,
                ns: Sequence[int]) -> dict[int, float]:
    """Recall@N: the share of the queries with a true place whose nearest true place ranks
    within the first N (`true_place_ranks`)."""
    ranks = np.asarray(ranks)[np.asarray(has_true_place, bool)]
    if not ranks.size:
        return {}
    return {int(k): float(np.count_nonzero(ranks <= k) / ranks.size) for k in ns}
