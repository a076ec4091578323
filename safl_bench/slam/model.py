"""What goes into the pose graph: odometry with seeded drift and loop closures, in 2-D (x, y, yaw).

Every choice here is stated with its source in docs/reference/slam-stage.md; in short:

* **Odometry** is the ground-truth relative motion between consecutive poses with drift at one
  of `DRIFT_LEVELS`, each a translational error in % of the distance travelled and a heading
  error in degrees per 100 m, the two figures of KITTI's odometry benchmark, taken from
  published LiDAR-odometry results on KITTI. The drift of a step of length d is a systematic part
  (the whole run's translation scaled by 1 ± t and its heading turning by ± r per metre, signs
  drawn per seed) and a white part (zero-mean Gaussian noise of standard deviation t·d on x and
  on y, r·d on the heading), so that the systematic part alone has the level's KITTI figures.
  It depends on the seed and the poses only, so every method of a seed shares it.
* **A true closure** carries the ground-truth relative pose of its two frames with Gaussian
  registration noise (`REGISTRATION_SIGMA_M`, `REGISTRATION_SIGMA_DEG`).
* **A false closure** carries a relative pose drawn uniformly at random (translation within
  ± `OUTLIER_TRANSLATION_M` on each axis, heading over the whole circle): the random outlier model
  of the robust pose-graph literature's benchmarks (Sünderhauf and Protzel's switchable
  constraints, IROS 2012; the GNC paper's experiments, Yang et al., RA-L 2020).
  Each closure's noise is seeded by (seed, query, match), so two methods that accept the same
  closure give the back-end the same measurement.
* **The 3-20 m band** (a match neither at the true place nor beyond the false-positive radius;
  the recall tables leave it out as ambiguous) is a false closure here, which is the pessimistic
  reading. A LiDAR SLAM system registers such pairs before it trusts them: LIO-SAM looks for
  loop candidates within 15 m of the current pose (``historyKeyframeSearchRadius``,
  ``config/params.yaml`` line 85 at TixiaoShan/LIO-SAM ``0be1fbe``), aligns them by ICP with
  correspondences up to twice that (``src/mapOptmization.cpp`` line 560) and keeps a closure
  only when ICP converged with a fitness score <= 0.3 (line 572). So a match a few metres off
  often becomes a good constraint after registration, while one whose views overlap little
  fails the check; neither is a uniformly random pose. What registration would give is not
  simulated: the loop-closure tables state how the band is counted and how many of a row's
  false closures lie in it (`safl_bench.leaderboard.slam_table`), and a method that gives its
  own relative pose (MapClosures) enters with that pose instead.
* **A method's own estimate**: where the record holds the method's relative pose for a query
  (`QueryOutcomes.relative_pose`: the matched frame's pose in the query's frame, as MapClosures'
  RANSAC alignment gives it), that estimate, inverted into this module's convention (the query's
  pose in the match's frame), is the closure's measurement instead of the simulated one, true
  and false closures alike (`Closures.estimated` says which).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from safl_bench.errors import ConfigError


@dataclass(frozen=True)
class DriftLevel:
    """Odometry drift as KITTI's odometry benchmark reports it, and where the figures come from."""

    name: str
    translation_pct: float  # % of the distance travelled
    heading_deg_per_100m: float
    source: str

    @property
    def translation_per_m(self) -> float:
        return self.translation_pct / 100.0

    @property
    def heading_rad_per_m(self) -> float:
        return math.radians(self.heading_deg_per_100m) / 100.0

    def describe(self) -> str:
        return f"{self.name} ({self.translation_pct:g} %, {self.heading_deg_per_100m:g} deg/100 m)"


DRIFT_LEVELS: dict[str, DriftLevel] = {
    level.name: level for level in (
        DriftLevel("low", 0.5, 0.18,
                   "state-of-the-art LiDAR odometry on KITTI 00-10: KISS-ICP's paper reports 0.49 % "
                   "(PRBonn/kiss-icp issue 315); SiMpLE's devkit figures on sequence 00 are "
                   "0.51 % and 0.18 deg/100 m (vb44/SiMpLE issue 3)"),
        DriftLevel("mid", 1.0, 0.35,
                   "what users reproduce with those open pipelines: 0.6 % for KISS-ICP "
                   "(PRBonn/kiss-icp issue 315), 0.81-1.2 % for F-LOAM, which reports 0.51 % "
                   "(wh200720041/floam issue 23); heading in SiMpLE's ratio of heading to "
                   "translation error"),
        DriftLevel("high", 3.0, 0.43,
                   "a camera-grade front end: Stereo DSO on KITTI 05, 2.96 % and 0.432 deg/100 m "
                   "(the evaluation plot attached to JiatianWu/stereo-dso)"),
    )
}
DEFAULT_DRIFT = "mid"

#: Standard deviations of a true closure's registration noise (this benchmark's choice: the
#: order of a LiDAR scan registration's error on KITTI; not taken from a publication).
REGISTRATION_SIGMA_M = 0.1
REGISTRATION_SIGMA_DEG = 0.5
#: A false closure's translation is uniform within this many metres on each axis.
OUTLIER_TRANSLATION_M = 10.0
#: Floors of the odometry factors' standard deviations (a vehicle standing still).
MIN_SIGMA_M = 0.01
MIN_SIGMA_RAD = 1e-4


def drift_level(name: str) -> DriftLevel:
    level = DRIFT_LEVELS.get(name)
    if level is None:
        raise ConfigError(f"unknown odometry drift level {name!r}; levels: {', '.join(DRIFT_LEVELS)}")
    return level


def wrap(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3) pose of `b` in the frame of `a` (SE(2): a^-1 b)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([c * dx + s * dy, -s * dx + c * dy, wrap(b[..., 2] - a[..., 2])], axis=-1)


def compose(a: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(..., 3) pose `a` moved by `d` in its own frame (SE(2): a d)."""
    a, d = np.asarray(a, np.float64), np.asarray(d, np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([a[..., 0] + c * d[..., 0] - s * d[..., 1],
                     a[..., 1] + s * d[..., 0] + c * d[..., 1], wrap(a[..., 2] + d[..., 2])], axis=-1)


def integrate(start: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """(n + 1, 3) poses from `start` through the (n, 3) relative `steps` (dead reckoning)."""
    out = np.empty((len(steps) + 1, 3))
    out[0] = start
    for k, step in enumerate(steps):
        out[k + 1] = compose(out[k], step)
    return out


@dataclass(frozen=True)
class Odometry:
    """The measured relative motions (n - 1, 3), the standard deviations of their factors
    (n - 1, 3), and the trajectory they integrate to from the true start (n, 3)."""

    steps: np.ndarray
    sigmas: np.ndarray
    trajectory: np.ndarray
    level: DriftLevel


def simulate_odometry(poses: np.ndarray, level: DriftLevel, seed: int) -> Odometry:
    """Odometry over the (n, 3) ground-truth `poses` with `level`'s drift (module doc), seeded by
    `seed` alone."""
    poses = np.asarray(poses, np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3 or len(poses) < 2:
        raise ConfigError(f"odometry needs (n >= 2, 3) poses, got {poses.shape}")
    true = between(poses[:-1], poses[1:])
    length = np.hypot(true[:, 0], true[:, 1])
    rng = np.random.default_rng([int(seed), 39, 1])
    t, r = level.translation_per_m, level.heading_rad_per_m
    scale = t * rng.choice([-1.0, 1.0])
    turn = r * rng.choice([-1.0, 1.0])
    sigmas = np.column_stack([np.maximum(t * length, MIN_SIGMA_M), np.maximum(t * length, MIN_SIGMA_M),
                              np.maximum(r * length, MIN_SIGMA_RAD)])
    steps = true.copy()
    steps[:, :2] *= 1.0 + scale
    steps[:, 2] += turn * length
    steps += rng.standard_normal(steps.shape) * np.column_stack([t * length, t * length, r * length])
    steps[:, 2] = wrap(steps[:, 2])
    return Odometry(steps=steps, sigmas=sigmas, trajectory=integrate(poses[0], steps), level=level)


@dataclass(frozen=True)
class Closures:
    """Accepted loop closures: factor from pose `match` to pose `query`, its measured relative
    pose, whether it is true, the detector's confidence."""

    query: np.ndarray  # (k,) int64, pose index
    match: np.ndarray  # (k,) int64, pose index
    measured: np.ndarray  # (k, 3) pose of `query` in the frame of `match`
    true: np.ndarray  # (k,) bool
    confidence: np.ndarray  # (k,) float64
    #: (k,) bool: the measurement is the method's own estimate, not simulated (None: none is)
    estimated: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.query)


def closure_measurements(poses: np.ndarray, query: np.ndarray, match: np.ndarray, true: np.ndarray,
                         confidence: np.ndarray, seed: int,
                         relative_pose: np.ndarray | None = None) -> Closures:
    """The measured relative poses of accepted closures (module doc): true ones the ground truth
    with registration noise, false ones uniformly random; where `relative_pose` (k, 3), the
    method's estimate of the match's pose in the query's frame, has a finite row, that estimate
    (inverted) instead."""
    poses = np.asarray(poses, np.float64)
    query, match = np.asarray(query, np.int64), np.asarray(match, np.int64)
    true = np.asarray(true, bool)
    measured = np.empty((len(query), 3))
    sigma = np.array([REGISTRATION_SIGMA_M, REGISTRATION_SIGMA_M, math.radians(REGISTRATION_SIGMA_DEG)])
    for k, (q, j, ok) in enumerate(zip(query.tolist(), match.tolist(), true.tolist(), strict=True)):
        rng = np.random.default_rng([int(seed), 39, 2, q, j])
        if ok:
            noise = rng.standard_normal(3) * sigma
            measured[k] = compose(between(poses[j], poses[q]), noise)
        else:
            xy = rng.uniform(-OUTLIER_TRANSLATION_M, OUTLIER_TRANSLATION_M, 2)
            measured[k] = [xy[0], xy[1], rng.uniform(-np.pi, np.pi)]
    estimated: np.ndarray | None = None
    if relative_pose is not None:
        own = np.asarray(relative_pose, np.float64).reshape(len(query), 3)
        estimated = np.asarray(np.isfinite(own).all(axis=1), bool)
        # T_query^-1 T_match inverted: the query's pose in the match's frame
        measured[estimated] = between(own[estimated], np.zeros(3))
    return Closures(query=query, match=match, measured=measured, true=true,
                    confidence=np.asarray(confidence, np.float64), estimated=estimated)
