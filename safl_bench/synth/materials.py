"""Surface materials of the synthetic town: LiDAR reflectance and porosity.

`PASS` is the probability that a ray crosses one raster cell of the material without a return
(vegetation, fences, hedges are porous; everything else is solid).
"""

from __future__ import annotations

import numpy as np

NONE = 0
ASPHALT = 1
MARKING = 2
SIDEWALK = 3
GRASS = 4
FACADE_A = 5
FACADE_B = 6
FACADE_C = 7
CAR = 8
TRUNK = 9
FOLIAGE = 10
POLE = 11
FENCE = 12
WALL = 13
HEDGE = 14
SIGN = 15
TALL_GRASS = 16
GLASS = 17  # a car's windows, with its seats behind them

FACADES = (FACADE_A, FACADE_B, FACADE_C)

#                       mean  sd    pass
_TABLE = {
    NONE: (0.0, 0.0, 1.0),
    ASPHALT: (0.30, 0.06, 0.0),
    MARKING: (0.70, 0.08, 0.0),
    SIDEWALK: (0.36, 0.07, 0.0),
    GRASS: (0.34, 0.10, 0.0),
    FACADE_A: (0.36, 0.08, 0.0),
    FACADE_B: (0.48, 0.10, 0.0),
    FACADE_C: (0.24, 0.07, 0.0),
    CAR: (0.38, 0.22, 0.0),
    TRUNK: (0.30, 0.05, 0.0),
    FOLIAGE: (0.30, 0.10, 0.72),
    POLE: (0.50, 0.12, 0.0),
    FENCE: (0.36, 0.10, 0.55),
    WALL: (0.33, 0.06, 0.0),
    HEDGE: (0.28, 0.08, 0.45),
    SIGN: (0.92, 0.05, 0.0),
    TALL_GRASS: (0.26, 0.09, 0.6),
    GLASS: (0.22, 0.10, 0.5),
}

N_MATERIALS = max(_TABLE) + 1
REFL_MEAN = np.zeros(N_MATERIALS, dtype=np.float32)
REFL_SD = np.zeros(N_MATERIALS, dtype=np.float32)
PASS = np.zeros(N_MATERIALS, dtype=np.float32)
for _m, (_mean, _sd, _pass) in _TABLE.items():
    REFL_MEAN[_m], REFL_SD[_m], PASS[_m] = _mean, _sd, _pass
