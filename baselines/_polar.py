"""Fast exact angular binning of 2-D points (numba), shared by Scan Context and M2DP.

`np.arctan2` costs ~30 ns a point, which alone would blow Scan Context's 2 ms budget on a
100k-point map. Instead the angle is approximated by a cheap polynomial (error < 2e-6 rad), turned
into a sector index, and the index is then corrected against the exact sector boundary
directions (the sign of a 2-D cross product), so the result equals
``floor(((atan2(y, x) - start) mod 2 pi) / w)`` with w = 2 pi / n, up to the float rounding of
the boundary vectors. The code is branch-free (selects) so that numba can vectorise the loops
that call it.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_TWO_PI = 2.0 * math.pi


@numba.njit(cache=True, inline="always", fastmath=True)
def angle_2pi(y: float, x: float) -> float:
    """atan2(y, x) mapped to [0, 2 pi), absolute error below 2e-6 rad (0 for the origin)."""
    ax = abs(x)
    ay = abs(y)
    swap = ay > ax
    num = ax if swap else ay
    den = ay if swap else ax
    t = num / den if den > 0.0 else 0.0
    t2 = t * t
    a = t * (0.99997726 + t2 * (-0.33262347 + t2 * (0.19354346 + t2 * (-0.11643287 + t2 * (0.05265332 + t2 * -0.01172120)))))
    a = 0.5 * math.pi - a if swap else a
    a = math.pi - a if x < 0.0 else a
    a = _TWO_PI - a if y < 0.0 else a
    return a


@numba.njit(cache=True, inline="always", fastmath=True)
def sector_index(y: float, x: float, start: float, n: int, cos_b: np.ndarray, sin_b: np.ndarray) -> int:
    """Index k in [0, n) of the sector [start + k w, start + (k + 1) w) holding direction (x, y).

    `cos_b[k]`, `sin_b[k]` are the unit vectors of the boundaries start + k w (`boundary_vectors`);
    `start` must lie in [-2 pi, 2 pi)."""
    rel = angle_2pi(y, x) - start
    rel = rel - _TWO_PI if rel >= _TWO_PI else rel
    rel = rel + _TWO_PI if rel < 0.0 else rel
    k = int(rel * (n / _TWO_PI))
    k = n - 1 if k >= n else k
    km = n - 1 if k == 0 else k - 1
    kp = 0 if k == n - 1 else k + 1
    before = cos_b[k] * y - sin_b[k] * x < 0.0
    past_next = cos_b[kp] * y - sin_b[kp] * x >= 0.0
    return km if before else (kp if past_next else k)


def boundary_vectors(n: int, start: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (cos, sin) of the n sector boundaries start + k 2 pi / n, float64."""
    angles = start + 2.0 * np.pi * np.arange(n) / n
    return np.cos(angles), np.sin(angles)


def quadrant_boundaries(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(cos, sin) of the inner sector boundaries of the first quadrant, j * 2 pi / n for
    j = 1 .. n/4 - 1 (for `sector_index_q`; n must be a multiple of 4)."""
    if n % 4:
        raise ValueError(f"quadrant binning needs a sector count divisible by 4, got {n}")
    angles = 2.0 * np.pi * np.arange(1, n // 4) / n
    return np.cos(angles), np.sin(angles)


@numba.njit(cache=True, inline="always", fastmath=True)
def sector_index_q(y: float, x: float, n: int, cq: np.ndarray, sq: np.ndarray) -> int:
    """Exact index k in [0, n) of the sector [k w, (k + 1) w), w = 2 pi / n, holding direction
    (x, y) (the origin: 0), for n a multiple of 4, without any arctangent: the direction is
    reflected into the upper half-plane (+n/2) and turned into the first quadrant (+n/4), both
    exactly, and then compared with the quadrant's boundary directions `cq`, `sq`
    (`quadrant_boundaries`). Branch-free and faster than `sector_index`."""
    m = n // 4
    lower = (y < 0.0) or (y == 0.0 and x < 0.0)
    x = -x if lower else x
    y = -y if lower else y
    quad = x <= 0.0 and y > 0.0
    t = x
    x = y if quad else x
    y = -t if quad else y
    k = 2 * m * lower + m * quad
    for j in range(m - 1):
        k += cq[j] * y - sq[j] * x >= 0.0
    return k
