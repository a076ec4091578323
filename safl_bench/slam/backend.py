"""The pose-graph back-ends (GTSAM) and the trajectory errors (evo).

The graph: one `Pose2` per pose, a tight prior holding the first at the truth, a between factor
per odometry step (Gaussian, the step's standard deviations, `model.Odometry.sigmas`) and one per
accepted closure (the registration noise of `model`). The initial estimate is the odometry's
dead-reckoned trajectory. Three back-ends solve it (`BACKENDS`):

* ``least-squares``: Levenberg-Marquardt, every factor Gaussian;
* ``cauchy``: the same with a Cauchy kernel (`CAUCHY_K`, in whitened units) on the closures;
* ``gnc-tls``: graduated non-convexity with a truncated-least-squares cost (GTSAM's
  `GncLMOptimizer`, Yang et al., RA-L 2020), prior and odometry factors known inliers, the
  closures' inlier threshold at the 0.999999 quantile of the chi-square distribution of their
  whitened error (`GNC_INLIER_PROBABILITY`).

A solve that does not converge is reported as such (`Solution.converged` False, with why), never
with its numbers: Levenberg-Marquardt has converged when it stopped before `MAX_ITERATIONS` with a
finite error; GNC with a truncated-least-squares cost has converged when every closure's weight
ended at 0 or 1 (within `WEIGHT_TOL`).

Errors (evo): ATE is the RMSE of the position error after aligning the estimate to the truth
(Umeyama, SE(3), no scale: the poses are in the plane, z = 0); RPE the RMSE of the translation
error of the relative motion over `rpe_delta_m` metres of the true path (every pair of poses
that far apart along it, within 10 %, as KITTI's devkit takes every start frame; pairs from the
reference, so every trajectory of a cell is measured on the same pairs); None when the path is
shorter than that.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from safl_bench.errors import ConfigError
from safl_bench.slam.model import (
    REGISTRATION_SIGMA_DEG,
    REGISTRATION_SIGMA_M,
    Closures,
    Odometry,
)

BACKENDS: tuple[str, ...] = ("least-squares", "cauchy", "gnc-tls")
MAX_ITERATIONS = 100
CAUCHY_K = 1.0
#: The closures' inlier threshold of GNC, a quantile of the chi-square distribution (3 degrees of
#: freedom) of their whitened error. At 0.99 GNC rejected every closure of a two-lap test loop at
#: the mid drift level, true ones included: the odometry's systematic drift is not in its noise
#: model, so true closures keep residuals beyond that quantile (tests/test_slam.py).
GNC_INLIER_PROBABILITY = 0.999999
WEIGHT_TOL = 1e-3
PRIOR_SIGMAS = (1e-3, 1e-3, 1e-4)


@dataclass(frozen=True)
class Solution:
    """One back-end's answer: the optimised (n, 3) trajectory (None when it did not converge),
    whether it converged and why not, and for GNC which closures it kept (weight > 0.5)."""

    backend: str
    converged: bool
    note: str
    trajectory: np.ndarray | None
    kept: np.ndarray | None = None  # (k,) bool, GNC only


def _graph(start: np.ndarray, odometry: Odometry, closures: Closures,
           robust: bool) -> tuple[Any, Any]:
    import gtsam

    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*start),
                                     gtsam.noiseModel.Diagonal.Sigmas(np.array(PRIOR_SIGMAS))))
    for k, (step, sigma) in enumerate(zip(odometry.steps, odometry.sigmas, strict=True)):
        graph.add(gtsam.BetweenFactorPose2(k, k + 1, gtsam.Pose2(*step),
                                           gtsam.noiseModel.Diagonal.Sigmas(sigma)))
    noise: Any = gtsam.noiseModel.Diagonal.Sigmas(np.array(
        [REGISTRATION_SIGMA_M, REGISTRATION_SIGMA_M, math.radians(REGISTRATION_SIGMA_DEG)]))
    if robust:
        noise = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Cauchy.Create(CAUCHY_K),
                                               noise)
    for q, j, measured in zip(closures.query.tolist(), closures.match.tolist(), closures.measured,
                              strict=True):
        graph.add(gtsam.BetweenFactorPose2(j, q, gtsam.Pose2(*measured), noise))
    initial = gtsam.Values()
    for i, pose in enumerate(odometry.trajectory):
        initial.insert(i, gtsam.Pose2(*pose))
    return graph, initial


def _poses(values: Any, n: int) -> np.ndarray:
    out = np.empty((n, 3))
    for i in range(n):
        p = values.atPose2(i)
        out[i] = (p.x(), p.y(), p.theta())
    return out


def solve(start: np.ndarray, odometry: Odometry, closures: Closures, backend: str) -> Solution:
    """Optimise the pose graph of `odometry` and `closures` from `start` (the first true pose)
    with `backend` (one of `BACKENDS`)."""
    import gtsam

    if backend not in BACKENDS:
        raise ConfigError(f"unknown back-end {backend!r}; back-ends: {', '.join(BACKENDS)}")
    n = len(odometry.trajectory)
    graph, initial = _graph(start, odometry, closures, robust=backend == "cauchy")
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(MAX_ITERATIONS)
    if backend != "gnc-tls":
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
        values = optimizer.optimize()
        iterations, error = optimizer.iterations(), optimizer.error()
        if not math.isfinite(error):
            return Solution(backend, False, f"the error is {error} after {iterations} iterations",
                            None)
        if iterations >= MAX_ITERATIONS:
            return Solution(backend, False, f"no convergence in {MAX_ITERATIONS} iterations", None)
        return Solution(backend, True, f"{iterations} iterations", _poses(values, n))
    gnc = gtsam.GncLMParams(params)
    gnc.setLossType(gtsam.GncLossType.TLS)
    gnc.setKnownInliers(list(range(n)))  # the prior (factor 0) and the n - 1 odometry factors
    graduated = gtsam.GncLMOptimizer(graph, initial, gnc)
    graduated.setInlierCostThresholdsAtProbability(GNC_INLIER_PROBABILITY)
    values = graduated.optimize()
    weights = np.asarray(graduated.getWeights(), np.float64)[n:]
    poses = _poses(values, n)
    if not np.isfinite(poses).all():
        return Solution(backend, False, "the optimised poses are not finite", None)
    undecided = int(np.sum(np.minimum(weights, 1.0 - weights) > WEIGHT_TOL))
    if undecided:
        return Solution(backend, False, f"{undecided} closure weights ended neither 0 nor 1", None)
    kept = weights > 0.5
    return Solution(backend, True, f"{int(kept.sum())} of {len(kept)} closures kept", poses, kept)


def _path(poses: np.ndarray) -> Any:
    from evo.core.trajectory import PosePath3D

    mats = []
    for x, y, yaw in np.asarray(poses, np.float64):
        m = np.eye(4)
        c, s = math.cos(yaw), math.sin(yaw)
        m[:2, :2] = [[c, -s], [s, c]]
        m[:2, 3] = (x, y)
        mats.append(m)
    return PosePath3D(poses_se3=mats)


@dataclass(frozen=True)
class Errors:
    """ATE RMSE after alignment (m), RPE RMSE over `delta_m` metres (m; None: path too short),
    and whether the estimate was aligned (not when the true path is a straight line, for which
    Umeyama's alignment is undefined: the errors are then in the frame of the first pose, which
    the graph's prior holds at the truth)."""

    ate_m: float
    rpe_m: float | None
    aligned: bool = True


def trajectory_errors(truth: np.ndarray, estimate: np.ndarray, rpe_delta_m: float) -> Errors:
    """evo's APE (after alignment) and RPE of `estimate` against `truth`, both (n, 3)."""
    from evo.core import filters, geometry, metrics
    from evo.core.metrics import PoseRelation, Unit

    reference, est = _path(truth), _path(estimate)
    aligned = True
    try:
        est.align(reference)
    except geometry.GeometryException:  # collinear positions
        est, aligned = _path(estimate), False
    ape = metrics.APE(PoseRelation.translation_part)
    ape.process_data((reference, est))
    ate = float(ape.get_statistic(metrics.StatisticsType.rmse))
    rpe_value: float | None = None
    rpe = metrics.RPE(PoseRelation.translation_part, delta=rpe_delta_m, delta_unit=Unit.meters,
                      all_pairs=True, pairs_from_reference=True)
    try:
        rpe.process_data((_path(truth), _path(estimate)))
        rpe_value = float(rpe.get_statistic(metrics.StatisticsType.rmse))
    except filters.FilterException:
        rpe_value = None
    return Errors(ate_m=ate, rpe_m=rpe_value, aligned=aligned)
