"""The second method kind: retrieval with verification.

A descriptor method (`safl_bench.methods.method.Method`) turns each map into a vector and lets
the harness compare every query with every database frame (a difference matrix, which the
sequence matcher reads). A RETRIEVAL method instead answers each query with a short ranked list
of database frames it has verified, each with a confidence (MapClosures: ORB features, a
Hamming search tree, a 2-D RANSAC alignment, confidence = its inliers; STD, Contour Context and
any method that checks candidates geometrically work the same way)::

    class MyRetrieval(RetrievalMethod):
        name, version = "my_retrieval", "1"
        def retrieve(self, queries, database, *, db_limit=None, same_frames=False):
            ...                                    # per query: candidates + confidences
            return Retrieval.from_lists(index, confidence)

Choices, with the reason for each:

* Declared by the class: ``kind = "retrieval"`` (a `ClassVar`, "descriptor" on `Method`), so the
  harness knows what to call without running anything, and descriptor methods pay one attribute
  read for it. `RetrievalMethod` sets it and refuses `describe`/`distance`.
* One call per cell, `retrieve(queries, database, db_limit=..., same_frames=...)`, not one per
  query: online methods (MapClosures adds each map to its database as it answers) need the
  order, and a batch call lets them keep their state inside. ``db_limit[i]``: query i may match
  only database frames ``j < db_limit[i]`` (the revisit protocol's time window; None: all), the
  form the shared matcher takes (`GroundTruth.db_limit`). ``same_frames``: the queries ARE the
  database frames, in time order (revisit tasks), so an online method feeds each frame once.
* The harness enforces the candidate rule: whatever a method returns beyond ``db_limit`` is
  dropped before anything is scored, so a method cannot win by ignoring the rule.
* Confidence is higher = more confident (a count of inliers, a similarity); the harness ranks by
  it and, among equal confidences, by the lower database index: the tie rule of every other
  method (`safl_bench.evaluation.metrics`, "Ties"). A database frame a method does not return is
  not retrieved: a query none of whose true places was returned counts at no N of Recall@N (its
  rank is recorded as `NOT_RETRIEVED`), so Recall@1 equals the single-frame recall_at_1 as for every
  method, and Recall@N reads only what the method listed.
* Single-frame matching is the top of that ranking; Recall@N and every measure are computed by
  the same code as for descriptor methods, on a difference matrix built from the ranking (minus
  the confidence where a frame was returned, +inf elsewhere). The SEQUENCE matcher needs a full
  difference matrix (SeqSLAM's contrast enhancement reads every database frame of a row) and a
  retrieval method gives none: its records hold no "sequence" result, and tables print
  "n/a (retrieval)" there rather than a number.
* Optional relative pose per candidate: [x m, y m, yaw rad], the candidate's pose in the query's
  frame (T_query^-1 T_candidate in SE(2)); records keep it for the matched frame
  (`Outcomes.relative_pose`), for the loop-closure stage.
* Timing: `Retrieval.seconds` holds the method's own time per query (for MapClosures: density
  map, features, search and RANSAC; everything its call does). A record's
  ``describe_ms_per_frame`` is their median; ``describe_frames_per_s`` the queries per second of
  the whole harness call (ranking and scoring included).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from safl_bench.errors import ConfigError, DataError
from safl_bench.methods.method import METHOD_KINDS, Method, Views

__all__ = ["METHOD_KINDS", "NOT_RETRIEVED", "NO_SEQUENCE", "NO_SEQUENCE_WHY", "Retrieval", "RetrievalMethod",
           "is_retrieval"]

#: The rank recorded for a query none of whose true places the method returned: beyond any N.
NOT_RETRIEVED = 2**31 - 1

#: What tables and the run summary print for a retrieval method's sequence-matcher cells.
NO_SEQUENCE = "n/a (retrieval)"

#: Why, in one line (records' notes, docs, the run summary).
NO_SEQUENCE_WHY = ("a retrieval method gives ranked candidates, no difference matrix, so the "
                   "sequence matcher cannot run")


@dataclass(frozen=True)
class Retrieval:
    """A retrieval method's answers, padded to k columns (k >= 0, the longest list).

    index: (Nq, k) int64, database frames, -1 = padding; confidence: (Nq, k) float64, higher =
    more confident, -inf at padding; pose: (Nq, k, 3) float64 [x, y, yaw] of each candidate in
    the query's frame (NaN = none), or None when the method estimates no pose; seconds: (Nq,)
    the method's own time per query (None: not measured per query)."""

    index: np.ndarray
    confidence: np.ndarray
    pose: np.ndarray | None = None
    seconds: np.ndarray | None = None

    @classmethod
    def from_lists(cls, index: Sequence[Sequence[int]], confidence: Sequence[Sequence[float]],
                   *, pose: Sequence[Sequence[Sequence[float]]] | None = None,
                   seconds: Sequence[float] | None = None) -> Retrieval:
        """From one list per query (of any lengths, equal per query)."""
        k = max((len(row) for row in index), default=0)
        n = len(index)
        idx = np.full((n, k), -1, np.int64)
        conf = np.full((n, k), -np.inf)
        pos = None if pose is None else np.full((n, k, 3), np.nan)
        if len(confidence) != n or (pose is not None and len(pose) != n):
            raise DataError(f"retrieval: {n} index lists but {len(confidence)} confidence lists"
                            + ("" if pose is None else f" and {len(pose)} pose lists"))
        for i, row in enumerate(index):
            if len(confidence[i]) != len(row) or (pose is not None and len(pose[i]) != len(row)):
                raise DataError(f"retrieval: query {i} has {len(row)} candidates but "
                                f"{len(confidence[i])} confidences")
            idx[i, :len(row)] = row
            conf[i, :len(row)] = confidence[i]
            if pos is not None and pose is not None and len(row):
                pos[i, :len(row)] = np.asarray(pose[i], np.float64).reshape(len(row), 3)
        secs = None if seconds is None else np.asarray(seconds, np.float64)
        return cls(idx, conf, pos, secs)

    def checked(self, n_queries: int, n_database: int, who: str) -> Retrieval:
        """Self, after checking shapes and values; DataError in one line naming `who`."""
        idx, conf = np.asarray(self.index), np.asarray(self.confidence, np.float64)
        if idx.ndim != 2 or idx.shape[0] != n_queries or conf.shape != idx.shape:
            raise DataError(f"{who}: retrieve() must give (Nq={n_queries}, k) index and confidence "
                            f"arrays, got {idx.shape} and {conf.shape}")
        if idx.size and not np.issubdtype(idx.dtype, np.integer):
            raise DataError(f"{who}: candidate indices must be integers, got {idx.dtype}")
        real = idx >= 0
        if (idx < -1).any() or (idx >= n_database).any():
            raise DataError(f"{who}: a candidate index lies outside the database [0, {n_database})")
        if np.isnan(conf).any() or np.isposinf(conf).any() or np.isinf(conf[real]).any():
            raise DataError(f"{who}: candidate confidences must be finite (padding -inf)")
        for i in np.flatnonzero(real.sum(axis=1) > 0):
            row = idx[i][real[i]]
            if np.unique(row).size != row.size:
                raise DataError(f"{who}: query {i} lists database frame "
                                f"{int(row[np.argmax(np.bincount(row))])} twice")
        if self.pose is not None and np.asarray(self.pose).shape != (*idx.shape, 3):
            raise DataError(f"{who}: pose must have shape {(*idx.shape, 3)}, "
                            f"got {np.asarray(self.pose).shape}")
        if self.seconds is not None and np.asarray(self.seconds).shape != (n_queries,):
            raise DataError(f"{who}: seconds must have one value per query ({n_queries})")
        return Retrieval(idx.astype(np.int64), conf, None if self.pose is None else
                         np.asarray(self.pose, np.float64), self.seconds)

    def as_difference(self, n_database: int, db_limit: np.ndarray | None = None) -> np.ndarray:
        """(Nq, Ndb) float64: minus each returned candidate's confidence, +inf for frames not
        returned and for those the candidate rule forbids (``j >= db_limit[i]``): the ranking
        (lower = nearer) that the shared tie rule and `true_place_ranks` read."""
        n = self.index.shape[0]
        D = np.full((n, n_database), np.inf)
        rows, cols = np.nonzero(self.index >= 0)
        D[rows, self.index[rows, cols]] = -self.confidence[rows, cols]
        if db_limit is not None:
            D[np.arange(n_database)[None, :] >= np.asarray(db_limit)[:, None]] = np.inf
        return D

    def pose_of(self, query: int, frame: int) -> np.ndarray:
        """[x, y, yaw] the method gave for database `frame` as a candidate of `query` (NaN if
        none)."""
        if self.pose is None or frame < 0:
            return np.full(3, np.nan)
        where = np.flatnonzero(self.index[query] == frame)
        return self.pose[query, where[0]] if where.size else np.full(3, np.nan)


class RetrievalMethod(Method):
    """Base class of retrieval methods (module docstring): subclass, set `name`/`version`,
    implement `retrieve`."""

    kind: ClassVar[str] = "retrieval"
    #: False for methods whose answers vary between identical runs (MapClosures' RANSAC draws
    #: from std::random_device); `check_method` then skips its determinism check for them.
    deterministic: ClassVar[bool] = True

    def retrieve(self, queries: Views, database: Views, *, db_limit: np.ndarray | None = None,
                 same_frames: bool = False) -> Retrieval:
        """Ranked, verified candidates of each query among `database` (module docstring)."""
        raise NotImplementedError(f"{type(self).__name__} must implement retrieve()")

    def describe(self, maps: Views) -> np.ndarray:
        raise ConfigError(f"method {self.name!r} is a retrieval method: it answers queries "
                          "(retrieve) and gives no descriptors")

    def distance(self, queries: np.ndarray, database: np.ndarray) -> np.ndarray:
        raise ConfigError(f"method {self.name!r} is a retrieval method: it has no distance")


def is_retrieval(method: Any) -> bool:
    """True for a method (instance or class) of the retrieval kind."""
    return getattr(method, "kind", "descriptor") == "retrieval"


def is_deterministic(method: Any) -> bool:
    """False for a method (instance or class) whose answers vary between identical runs
    (``deterministic = False``); True for every other, which need not declare it."""
    return bool(getattr(method, "deterministic", True))
