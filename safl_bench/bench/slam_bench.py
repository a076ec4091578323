"""Benchmark of one loop-closure cell at KITTI 00's size (issue 39: at most 10 s on the 2-core
machine).

    safl-bench bench slam [--repeats 3]

The cell is built here, with no data: `N_POSES` poses (KITTI 00 has 4541 frames) along a block
of streets driven twice, a pose about every 0.8 m (KITTI 00's 3.7 km over 4541 frames), with the
default (mid) drift; `N_TRUE` true closures (the second pass matched to the first) and `N_FALSE`
false ones (random pairs far apart), as a detector at a loose threshold gives. Each repeat times
what `slam.cell.run_slam` does after reading the record: simulate the odometry, the closures'
measurements, each back-end's solve and the errors (ATE, RPE by evo) of each trajectory and of
the odometry. Printed: the median over the repeats of the whole cell and of each part, after one
untimed warm-up (imports, GTSAM's first graph).
"""

from __future__ import annotations

import itertools
import statistics
import time
from dataclasses import dataclass

import numpy as np

from safl_bench.slam.backend import BACKENDS, solve, trajectory_errors
from safl_bench.slam.model import (
    DEFAULT_DRIFT,
    closure_measurements,
    drift_level,
    simulate_odometry,
)

N_POSES = 4541
N_TRUE = 300
N_FALSE = 20
LIMIT_S = 10.0


def kitti00_sized_cell(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(poses, query, match, true): a route of `N_POSES` poses (two passes of a 1.8 km block) and
    `N_TRUE` + `N_FALSE` closures (module doc)."""
    corners = np.array([[0, 0], [600, 0], [600, 300], [0, 300], [0, 0]], float)
    lap = N_POSES // 2
    perimeter = 1800.0
    points = []
    for a, b in itertools.pairwise(corners):
        n = round(lap * float(np.linalg.norm(b - a)) / perimeter)
        points += [a + (b - a) * k / n for k in range(n)]
    xy = np.array((points * 3)[:N_POSES])
    heading = np.arctan2(*(np.roll(xy, -1, axis=0) - xy)[:, ::-1].T)
    poses = np.column_stack([xy, heading])
    per_lap = len(points)
    query = np.linspace(per_lap, N_POSES - 1, N_TRUE).astype(np.int64)
    match = query - per_lap
    rng = np.random.default_rng(seed)
    wrong_q = rng.integers(per_lap, N_POSES, N_FALSE)
    wrong_m = (wrong_q - per_lap + per_lap // 2) % per_lap
    return (poses, np.r_[query, wrong_q], np.r_[match, wrong_m],
            np.r_[np.ones(N_TRUE, bool), np.zeros(N_FALSE, bool)])


@dataclass(frozen=True)
class SlamBench:
    """Median seconds over the repeats: the whole cell and each part."""

    repeats: int
    total_s: float
    parts_s: dict[str, float]
    ate_m: dict[str, float]


def _once(seed: int) -> tuple[dict[str, float], dict[str, float]]:
    poses, query, match, true = kitti00_sized_cell()
    times: dict[str, float] = {}
    ate: dict[str, float] = {}
    t0 = time.perf_counter()
    odometry = simulate_odometry(poses, drift_level(DEFAULT_DRIFT), seed)
    closures = closure_measurements(poses, query, match, true, np.ones(len(query)), seed)
    ate["odometry"] = trajectory_errors(poses, odometry.trajectory, 100.0).ate_m
    times["odometry, closures, odometry errors"] = time.perf_counter() - t0
    for name in BACKENDS:
        t = time.perf_counter()
        solution = solve(poses[0], odometry, closures, name)
        if solution.trajectory is not None:
            ate[name] = trajectory_errors(poses, solution.trajectory, 100.0).ate_m
        else:
            ate[name] = float("nan")
        times[name] = time.perf_counter() - t
    return times, ate


def run(repeats: int = 3) -> SlamBench:
    """Time the cell `repeats` times after one warm-up (module doc)."""
    _once(0)
    runs = [_once(r) for r in range(repeats)]
    parts = {k: statistics.median(t[k] for t, _ in runs) for k in runs[0][0]}
    total = statistics.median(sum(t.values()) for t, _ in runs)
    return SlamBench(repeats, total, parts, runs[0][1])


def format_results(result: SlamBench) -> str:
    lines = [f"one loop-closure cell of KITTI 00's size: {N_POSES} poses, {N_TRUE} true and "
             f"{N_FALSE} false closures, {len(BACKENDS)} back-ends; median of {result.repeats}",
             f"  whole cell: {result.total_s:.2f} s (limit {LIMIT_S:g} s: "
             f"{'within' if result.total_s <= LIMIT_S else 'OVER'})"]
    lines += [f"  {name:<38}{seconds:6.2f} s" + (f"   ATE {result.ate_m[name]:.2f} m"
                                                 if name in result.ate_m else "")
              for name, seconds in result.parts_s.items()]
    lines.append(f"  (odometry alone ATE {result.ate_m['odometry']:.2f} m)")
    return "\n".join(lines)
