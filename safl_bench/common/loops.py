"""The loop-pair definition: two frames within a radius whose times are far enough apart.

Shared by the ground truth (`safl_bench.evaluation.groundtruth`, which builds its true places on
it) and the synthetic generator (`safl_bench.synth.routes`, which plans routes that revisit
places): the generator comes before every stage, so the definition both read lives here.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from safl_bench.errors import ConfigError


def check_radius(name: str, value: float) -> float:
    """`value` as a float; ConfigError naming `name` unless it is a finite distance >= 0."""
    value = float(value)
    if not np.isfinite(value) or value < 0:
        raise ConfigError(f"{name} must be a finite distance >= 0 m, got {value!r}")
    return value


def loop_pairs(
    positions: np.ndarray, times: np.ndarray, radius: float, min_gap_s: float
) -> np.ndarray:
    """Every loop pair (query, match) of one sequence, as (P, 2) int64 sorted by query then match.

    A pair is two frames within `radius` metres in the ground plane where the match is strictly
    older than the query by more than `min_gap_s` seconds (t_query - t_match > min_gap_s).
    """
    positions = np.asarray(positions, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    radius = check_radius("radius", radius)
    min_gap_s = float(min_gap_s)
    if not np.isfinite(min_gap_s) or min_gap_s < 0:
        raise ConfigError(
            f"minimum time gap must be a finite number of seconds >= 0, got {min_gap_s!r}"
        )
    if positions.ndim != 2 or positions.shape[1] != 2 or len(times) != len(positions):
        raise ConfigError(
            f"need (n, 2) positions and n times, got {positions.shape} and {times.shape}"
        )
    pairs = cKDTree(positions).query_pairs(radius, output_type="ndarray").astype(np.int64)
    a, b = pairs[:, 0], pairs[:, 1]
    later_b = times[b] - times[a] > min_gap_s
    later_a = times[a] - times[b] > min_gap_s
    out = np.concatenate(
        [np.stack([b[later_b], a[later_b]], 1), np.stack([a[later_a], b[later_a]], 1)]
    )
    out = out.reshape(-1, 2)
    return out[np.lexsort((out[:, 1], out[:, 0]))]
