"""Ground truth from poses alone: which database frames are the same place as a query.

Both protocols measure positions in the ground plane (x, y of the LiDAR frame, which is x, z of
KITTI's camera frame) and compare `times.txt` stamps:

- paper protocol: every database frame is a candidate; a match is a true positive within
  `tp_radius` (10 m) and a false positive otherwise (`fp_radius == tp_radius`, no band);
- revisit protocol: a query may only match database frames strictly older than `window_s`
  seconds; a match is a true positive within `tp_radius` (3 m), a false positive beyond
  `fp_radius` (20 m), and excluded (neither) in the band between.

Neighbour searches use a KD-tree, so a KITTI-size sequence (4541 frames) takes milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from safl_bench.common.loops import check_radius as _check_radius
from safl_bench.common.loops import loop_pairs  # noqa: F401  (re-exported: defined there)
from safl_bench.errors import ConfigError, DataError
from safl_bench.sources import kitti

#: Labels of an answered match (`GroundTruth.labels`).
TP, EXCLUDED, FP = 1, 0, -1

#: Frame period assumed when no `times.txt` is given (KITTI's LiDAR runs at 10 Hz).
DEFAULT_PERIOD_S = 0.1


def read_poses(path: str | Path) -> np.ndarray:
    """Read any KITTI poses file (12 numbers per line, row-major 3x4) as camera poses (n, 4, 4)."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: poses file does not exist or is not a file")
    try:
        n = sum(1 for line in path.read_text().splitlines() if line.strip())
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a text file ({exc.reason})") from None
    if n == 0:
        raise DataError(f"{path}: holds no poses")
    return kitti.read_camera_poses(path, n)


def read_times(path: str | Path, n: int) -> np.ndarray:
    """Read a KITTI `times.txt` (one stamp in seconds per line) holding exactly `n` stamps."""
    return kitti.read_times(Path(path), n)


def camera_ground_positions(poses: np.ndarray) -> np.ndarray:
    """Ground-plane positions (n, 2) of KITTI camera-frame poses (n, 3|4, 4): camera x and z."""
    return np.ascontiguousarray(poses[:, [0, 2], 3], dtype=np.float64)


def default_times(n: int, period_s: float = DEFAULT_PERIOD_S) -> np.ndarray:
    """Evenly spaced stamps i * period_s (computed as i / rate so that they are exact decimals)."""
    return np.arange(n, dtype=np.float64) / (1.0 / period_s)


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """Which database frames a query may match and which of them are the same place.

    Positions are (n, 2) ground-plane metres; times are seconds. `window_s=None` makes every
    database frame a candidate (paper protocol); otherwise a candidate must be strictly older than
    the query by more than `window_s` seconds. A match to a frame that is not a candidate counts as
    a false positive (it was not allowed), whatever its distance.
    """

    query_positions: np.ndarray
    database_positions: np.ndarray
    query_times: np.ndarray
    database_times: np.ndarray
    tp_radius: float
    fp_radius: float
    window_s: float | None = None
    _true: list[np.ndarray] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        tp = _check_radius("true-positive radius", self.tp_radius)
        fp = _check_radius("false-positive radius", self.fp_radius)
        if fp < tp:
            raise ConfigError(
                f"false-positive radius {fp} m is below the true-positive radius {tp} m"
            )
        if self.window_s is not None and (not np.isfinite(self.window_s) or self.window_s < 0):
            raise ConfigError(
                f"time window must be a finite number of seconds >= 0, got {self.window_s!r}"
            )
        for name in ("query_positions", "database_positions", "query_times", "database_times"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=np.float64))
        if self.query_positions.shape != (
            len(self.query_times),
            2,
        ) or self.database_positions.shape != (
            len(self.database_times),
            2,
        ):
            raise ConfigError(
                "ground truth needs (n, 2) positions and n times for queries and database"
            )
        object.__setattr__(self, "_true", self._find_true())

    def _find_true(self) -> list[np.ndarray]:
        nq = len(self.query_positions)
        out: list[list[int]] = [[] for _ in range(nq)]
        if nq and len(self.database_positions):
            near = cKDTree(self.query_positions).sparse_distance_matrix(
                cKDTree(self.database_positions), self.tp_radius, output_type="ndarray"
            )
            qi, dj = near["i"].astype(np.int64), near["j"].astype(np.int64)
            keep = self.is_candidate(qi, dj)
            for i, j in zip(qi[keep].tolist(), dj[keep].tolist(), strict=True):
                out[i].append(j)
        return [np.asarray(sorted(js), dtype=np.int64) for js in out]

    @property
    def n_queries(self) -> int:
        return len(self.query_positions)

    @property
    def n_database(self) -> int:
        return len(self.database_positions)

    def is_candidate(self, query: np.ndarray | int, match: np.ndarray | int) -> np.ndarray:
        """Whether query `query` may match database frame `match` (elementwise)."""
        query, match = np.asarray(query), np.asarray(match)
        if self.window_s is None:
            return np.ones(np.broadcast(query, match).shape, dtype=bool)
        return self.query_times[query] - self.database_times[match] > self.window_s

    def candidate_mask(self) -> np.ndarray:
        """(Nq, Ndb) bool: the database frames each query may match."""
        if self.window_s is None:
            return np.ones((self.n_queries, self.n_database), dtype=bool)
        return self.query_times[:, None] - self.database_times[None, :] > self.window_s

    def db_limit(self) -> np.ndarray:
        """(Nq,) int64: query i may match exactly the database frames j < db_limit[i].

        This is the form the shared matcher takes (`matching.seqslam(..., db_limit=...)`); it
        exists when every query's candidates are a prefix of the database (database in time
        order), which holds for both built-in protocols. Raises ConfigError otherwise.
        """
        mask = self.candidate_mask()
        limit = mask.sum(axis=1).astype(np.int64)
        prefix = np.arange(self.n_database)[None, :] < limit[:, None]
        if not np.array_equal(mask, prefix):
            raise ConfigError("the candidates of some query are not a prefix of the database")
        return limit

    def distances(self, query: np.ndarray | int, match: np.ndarray | int) -> np.ndarray:
        """Ground-plane distance (m) between queries and database frames (elementwise)."""
        diff = self.query_positions[np.asarray(query)] - self.database_positions[np.asarray(match)]
        return np.hypot(diff[..., 0], diff[..., 1])

    def true_matches(self, query: int) -> np.ndarray:
        """Candidate database indices within the true-positive radius of query `query`."""
        return self._true[query]

    @property
    def has_candidate(self) -> np.ndarray:
        """(Nq,) bool: queries that may match at least one database frame (the revisit
        protocol's queries younger than the time window have none)."""
        if self.n_database == 0:
            return np.zeros(self.n_queries, dtype=bool)
        if self.window_s is None:
            return np.ones(self.n_queries, dtype=bool)
        return self.query_times - self.database_times.min() > self.window_s

    @property
    def has_loop(self) -> np.ndarray:
        """(Nq,) bool: queries with at least one true match among their candidates."""
        return np.array([len(t) > 0 for t in self._true], dtype=bool)

    def pairs(self) -> np.ndarray:
        """All true (query, database) pairs as (P, 2) int64, sorted by query then match."""
        rows = [
            np.stack([np.full(len(t), i, dtype=np.int64), t], 1) for i, t in enumerate(self._true)
        ]
        return np.concatenate(rows) if rows else np.zeros((0, 2), dtype=np.int64)

    def labels(self, matches: np.ndarray) -> np.ndarray:
        """Label each query's answered match (Nq,) int8: TP (1), FP (-1) or EXCLUDED (0).

        A non-candidate answer is FP; an answer in the band tp_radius < d <= fp_radius is EXCLUDED.
        """
        matches = np.asarray(matches, dtype=np.int64)
        if matches.shape != (self.n_queries,):
            raise ConfigError(
                f"need one match per query ({self.n_queries}), got shape {matches.shape}"
            )
        if self.n_queries and (matches.min() < 0 or matches.max() >= self.n_database):
            raise ConfigError(
                f"match indices must lie in [0, {self.n_database}), got {matches.min()}..{matches.max()}"
            )
        return self.label_of(np.arange(self.n_queries), matches)

    def label_of(self, query: np.ndarray | int, match: np.ndarray | int) -> np.ndarray:
        """Elementwise label of answering database frame `match` for query `query`."""
        dist = self.distances(query, match)
        label = np.where(dist <= self.tp_radius, TP, np.where(dist > self.fp_radius, FP, EXCLUDED))
        label = np.where(self.is_candidate(query, match), label, FP)
        return label.astype(np.int8)
