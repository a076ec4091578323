"""`MapConfig`: every setting that changes a local map or a rendered top view.

The whole dataclass goes into the map-cache key and into result records, so two runs with
different settings never share maps. The paper (II.A) gives no numbers for its maps; the
defaults below are ours and are documented here:

- local map: the last `window` scans (10, one second of KITTI), voxels of `voxel_m` (0.5 m),
  kept while within `radius_m` (50 m, measured in the ground plane) of the robot;
  occupancy in log-odds with OctoMap's default sensor model (hit 0.7, miss 0.4, clamping
  0.12..0.97, occupied above 0.5).
- top view: `size` x `size` pixels (64) covering `extent_m` x `extent_m` (80 m) centred on the
  viewpoint, forward = up (row 0 is farthest ahead), left = left (column 0 is farthest left).
- heights are measured above the ground under the robot, taken as `sensor_height_m` (1.73 m,
  KITTI's Velodyne) below the sensor ("flat ground"): voxel centres below `ground_clearance_m`
  are ground, those from there up to `max_height_m` are obstacles, others are ignored.
- encoding "occupancy" (default), like octomap_server's projected map: a pixel holding an
  obstacle voxel is 1.0, one holding only ground (observed, drivable) is `ground_value` (0.5),
  one with nothing is 0.0 (unknown). Encoding "height": obstacles are
  0.5 + 0.5 * min(height / max_height_m, 1), ground 0.25, unknown 0.
- encoding "bev-density": BEVPlace's bird's-eye-view images (Luo et al., ICCV 2023), rendered
  from the raw points of the last `window` scans rather than from the local map; the steps and
  the evidence for each are in `safl_bench.views.bevdensity`. Use `bev_density_config()`, which sets
  every field to BEVPlace's values; for this encoding some fields read differently:

  - `size` 151 (odd sizes are allowed for this encoding only: the sensor pixel is the centre
    pixel (size - 1) / 2), `extent_m` 60.4 (`cell_m` 0.4 m per pixel);
  - `voxel_m` 0.3: the voxel grid whose occupied voxels are counted, aligned with the
    viewpoint (also the local map's voxel, for the points views);
  - `window` 1: BEVPlace renders single scans (its images of consecutive frames differ by what
    one scan sees; nothing in its code or images suggests accumulation);
  - `radius_m` 25: the half-width of a *square* crop, |x| < 25 m and |y| < 25 m in the
    viewpoint frame, as BEVPlace's script crops (the published images have no pixel beyond
    24.8 m of the sensor along either axis);
  - `min_height_m` 0.53 and `max_height_m` 26.73: points are kept when their height above the
    ground (z + `sensor_height_m`) is strictly between the two, i.e. sensor-frame
    -1.2 m < z < 25 m: BEVPlace's |z| < 25 m and the ground cut at z = -1.2 m that its
    published images show (the script does not);
  - `ground_clearance_m`, `ground_value` and the occupancy probabilities do not change the
    image (they still shape the local map of the points views).

  The count clip (10) and the dropped counts (none: single counts are kept, as in the published
  images) are the constants `bevdensity.DENSITY_CAP` and `bevdensity.DENSITY_MIN_COUNT`; their
  values are part of the encoding, so changing either means a new encoding name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

from safl_bench.errors import ConfigError

BACKENDS = ("voxel", "octomap")
ENCODINGS = ("occupancy", "height", "bev-density")
#: BEVPlace's image geometry: 151 x 151 pixels of 0.4 m, the sensor at the centre pixel (75, 75).
BEV_DENSITY_SIZE = 151
BEV_DENSITY_CELL_M = 0.4


def logodds(p: float) -> float:
    """log(p / (1 - p))."""
    return math.log(p / (1.0 - p))


@dataclass(frozen=True)
class MapConfig:
    """Settings of the sliding local map and of the top-view projection (see module doc)."""

    size: int = 64
    extent_m: float = 80.0
    voxel_m: float = 0.5
    window: int = 10
    radius_m: float = 50.0
    backend: str = "voxel"
    encoding: str = "occupancy"
    sensor_height_m: float = 1.73
    ground_clearance_m: float = 0.6
    min_height_m: float = -1.5
    max_height_m: float = 4.0
    ground_value: float = 0.5
    prob_hit: float = 0.7
    prob_miss: float = 0.4
    prob_occupied: float = 0.5
    clamp_min: float = 0.12
    clamp_max: float = 0.97

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ConfigError(f"map backend must be one of {', '.join(BACKENDS)}, got {self.backend!r}")
        if self.encoding not in ENCODINGS:
            raise ConfigError(f"map encoding must be one of {', '.join(ENCODINGS)}, got {self.encoding!r}")
        if self.encoding == "bev-density":
            if not isinstance(self.size, int) or self.size < 2:
                raise ConfigError(f"map size must be an integer >= 2, got {self.size!r}")
        elif not isinstance(self.size, int) or self.size < 2 or self.size % 2:
            raise ConfigError(f"map size must be an even integer >= 2, got {self.size!r}")
        if not isinstance(self.window, int) or self.window < 1:
            raise ConfigError(f"map window must be an integer >= 1 scans, got {self.window!r}")
        for label in ("extent_m", "voxel_m", "radius_m", "max_height_m"):
            value = getattr(self, label)
            if not math.isfinite(value) or value <= 0:
                raise ConfigError(f"{label} must be a finite value > 0, got {value!r}")
        if self.encoding == "bev-density":  # no ground band: ground_clearance_m is not used
            if not self.min_height_m < self.max_height_m:
                raise ConfigError(f"need min_height_m < max_height_m, got {self.min_height_m}, {self.max_height_m}")
        elif not self.min_height_m < self.ground_clearance_m < self.max_height_m:
            raise ConfigError(
                "need min_height_m < ground_clearance_m < max_height_m, got "
                f"{self.min_height_m}, {self.ground_clearance_m}, {self.max_height_m}"
            )
        if not 0.0 < self.ground_value < 1.0:
            raise ConfigError(f"ground_value must be in (0, 1), got {self.ground_value!r}")
        for label in ("prob_hit", "prob_miss", "prob_occupied", "clamp_min", "clamp_max"):
            value = getattr(self, label)
            if not 0.0 < value < 1.0:
                raise ConfigError(f"{label} must be a probability in (0, 1), got {value!r}")
        if not self.clamp_min < self.prob_occupied < self.clamp_max or self.prob_hit <= 0.5:
            raise ConfigError("need clamp_min < prob_occupied < clamp_max and prob_hit > 0.5")

    @property
    def cell_m(self) -> float:
        """Side of one top-view pixel (m)."""
        return self.extent_m / self.size

    @property
    def insert_radius_m(self) -> float:
        """Points farther than this (ground plane) from their own scan's origin are not inserted.

        The map keeps voxels within `radius_m` of the *current* robot, which may have driven on
        since an older scan of the window; a margin of 3 m per scan (30 m/s at 10 Hz) keeps every
        point that can come within `radius_m` during the window. `radius_m` itself is applied
        exactly when the map is read.
        """
        return self.radius_m + 3.0 * self.window


def bev_density_config(**changes: Any) -> MapConfig:
    """BEVPlace's BEV-density encoding (module doc, `safl_bench.views.bevdensity`): 151 x 151 pixels
    of 0.4 m, a single scan, 0.3 m voxels, a 25 m square crop, sensor-frame -1.2 m < z < 25 m;
    `changes` override single fields (e.g. `window=3`, `backend="octomap"`)."""
    base = MapConfig(
        size=BEV_DENSITY_SIZE,
        extent_m=BEV_DENSITY_SIZE * BEV_DENSITY_CELL_M,
        voxel_m=0.3,
        window=1,
        radius_m=25.0,
        encoding="bev-density",
        min_height_m=0.53,
        max_height_m=26.73,
    )
    return replace(base, **changes) if changes else base


def config_for_encoding(encoding: str, **changes: Any) -> MapConfig:
    """The map settings of an encoding: `bev_density_config()` for "bev-density" (its size,
    voxel, window and crop come with it), the defaults otherwise; `changes` override fields."""
    if encoding == "bev-density":
        return bev_density_config(**changes)
    return replace(MapConfig(), encoding=encoding, **changes)
