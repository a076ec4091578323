"""Projection of a local map on the ground plane: top-view maps and viewpoint-frame points.

A viewpoint is (x, y, yaw) in the world frame. The top view is `size` x `size` pixels of
`cell_m` metres, centred on the viewpoint (the viewpoint sits at the corner shared by the four
central pixels) and aligned with its heading:

    row r    covers forward distance  x_v in [(size/2 - r - 1) * cell, (size/2 - r) * cell)
    column c covers leftward distance y_v in [(size/2 - c - 1) * cell, (size/2 - c) * cell)

so forward is up (row 0 is farthest ahead) and left is left (column 0 is farthest left).
Turning the viewpoint left by 90 degrees turns the image clockwise: np.rot90(image, -1).

Viewpoint noise (dx, dy, dtheta in the robot frame, `safl_bench.views.noise.sample_offsets`) moves
the viewpoint before projection (`noisy_viewpoints`); finished images are never warped.

Heights are measured above the ground under the robot (robot z - sensor_height_m); see
`MapConfig` for the bands and the encodings. Several voxels falling in one pixel combine by max,
so an obstacle anywhere in the pixel's column wins over ground.

The "bev-density" encoding (BEVPlace's images) is not drawn from the local map's voxels but
from the raw points of the window's scans, in `safl_bench.views.bevdensity`, with BEVPlace's own
geometry, which differs from the above: an image of any size (151 x 151) whose centre pixel
(c0, c0), c0 = (size - 1) / 2, holds the sensor, and row = c0 - trunc(x / cell),
col = c0 - trunc(y / cell) (truncation toward zero, so the centre row and column are two cells
wide). Forward is still up and left still left, so the same turns of the viewpoint turn the
image the same way (left by 90 degrees: np.rot90(image, -1), exact for this geometry), and the
viewpoint noise is applied the same way: by moving the viewpoint before rendering, never by
warping the image. `scan_topview(points, bev_density_config())` is exactly BEVPlace's image of
one scan (as PNG value / 255).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from safl_bench.errors import ConfigError
from safl_bench.views.mapconfig import MapConfig

UNKNOWN = 0.0
HEIGHT_GROUND_VALUE = 0.25


def pose_viewpoint(pose: np.ndarray) -> np.ndarray:
    """(x, y, yaw) of a 4x4 pose."""
    return np.array([pose[0, 3], pose[1, 3], math.atan2(pose[1, 0], pose[0, 0])])


def noisy_viewpoints(viewpoints: np.ndarray, offsets: np.ndarray | None) -> np.ndarray:
    """Move viewpoints (F, 3) by robot-frame offsets (F, 3) [dx forward, dy left, dtheta]."""
    vp = np.asarray(viewpoints, dtype=np.float64).reshape(-1, 3)
    if offsets is None:
        return vp.copy()
    off = np.asarray(offsets, dtype=np.float64).reshape(-1, 3)
    c, s = np.cos(vp[:, 2]), np.sin(vp[:, 2])
    return np.stack(
        [
            vp[:, 0] + c * off[:, 0] - s * off[:, 1],
            vp[:, 1] + s * off[:, 0] + c * off[:, 1],
            vp[:, 2] + off[:, 2],
        ],
        axis=1,
    )


def encode(centres: np.ndarray, robot_z: float, config: MapConfig) -> tuple[np.ndarray, np.ndarray]:
    """Pixel values of occupied voxels: (xy (K, 2) float64, value (K,) float32).

    Voxels below `min_height_m` or above `max_height_m` (above ground) are dropped.
    The "bev-density" encoding has no per-voxel value (it counts; `safl_bench.views.bevdensity`).
    """
    if config.encoding == "bev-density":
        raise ConfigError("the bev-density encoding is rendered from points (safl_bench.views.bevdensity), not encoded per voxel")
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    h = centres[:, 2] - (robot_z - config.sensor_height_m)
    keep = (h >= config.min_height_m) & (h <= config.max_height_m)
    h = h[keep]
    obstacle = h >= config.ground_clearance_m
    if config.encoding == "height":
        value = np.where(
            obstacle, 0.5 + 0.5 * np.minimum(h / config.max_height_m, 1.0), HEIGHT_GROUND_VALUE
        )
    else:
        value = np.where(obstacle, 1.0, config.ground_value)
    return np.ascontiguousarray(centres[keep, :2]), value.astype(np.float32)


@numba.njit(cache=True)
def _render(xy, value, viewpoints, size, cell, out):
    half = size / 2.0
    inv = 1.0 / cell
    for v in range(viewpoints.shape[0]):
        vx = viewpoints[v, 0]
        vy = viewpoints[v, 1]
        c = math.cos(viewpoints[v, 2])
        s = math.sin(viewpoints[v, 2])
        img = out[v]
        for i in range(xy.shape[0]):
            dx = xy[i, 0] - vx
            dy = xy[i, 1] - vy
            fwd = c * dx + s * dy
            left = -s * dx + c * dy
            r = math.floor(half - fwd * inv)
            col = math.floor(half - left * inv)
            if 0 <= r < size and 0 <= col < size and value[i] > img[r, col]:
                img[r, col] = value[i]


def render(xy: np.ndarray, value: np.ndarray, viewpoints: np.ndarray, config: MapConfig) -> np.ndarray:
    """Top views (V, size, size) float32 in [0, 1] of encoded voxels from viewpoints (V, 3)."""
    vps = np.ascontiguousarray(np.asarray(viewpoints, dtype=np.float64).reshape(-1, 3))
    out = np.zeros((len(vps), config.size, config.size), dtype=np.float32)
    if len(xy):
        _render(
            np.ascontiguousarray(xy, dtype=np.float64), np.ascontiguousarray(value, dtype=np.float32),
            vps, config.size, config.cell_m, out,
        )
    return out


def view_points(
    centres: np.ndarray, viewpoint: np.ndarray, robot_z: float, half_extent_m: float | None = None
) -> np.ndarray:
    """Local-map points (M, 3) float32 in the viewpoint frame (x forward, y left, z up, origin
    at the sensor height of the robot).

    With `half_extent_m` (the top view's `extent_m / 2`), only the points inside the top view's
    window are kept (-h < x <= h, -h < y <= h, the pixels `render` fills), so a points view and a
    top view of the same viewpoint show the same part of the map: moving the viewpoint changes
    what is seen, not only the coordinates (otherwise a descriptor that centres and aligns the
    cloud, like M2DP, would be blind to the viewpoint noise by construction).
    """
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    vx, vy, yaw = (float(v) for v in viewpoint)
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = centres[:, 0] - vx, centres[:, 1] - vy
    fwd, left = c * dx + s * dy, -s * dx + c * dy
    pts = np.stack([fwd, left, centres[:, 2] - robot_z], axis=1)
    if half_extent_m is not None:
        h = float(half_extent_m)
        pts = pts[(fwd > -h) & (fwd <= h) & (left > -h) & (left <= h)]
    return pts.astype(np.float32)


def scan_topview(points: np.ndarray, config: MapConfig | None = None) -> np.ndarray:
    """Top view (size, size) of one scan in its own sensor frame (no local map), for looking at.

    Points are voxelised first, so the encoding matches the map-based views. With the
    "bev-density" encoding this is BEVPlace's image of the scan (`safl_bench.views.bevdensity`).
    """
    from safl_bench.views.localmap import keys_to_centres, voxel_keys

    config = config or MapConfig()
    if config.encoding == "bev-density":
        from safl_bench.views.bevdensity import density_image

        return density_image(points, config)
    pts = np.asarray(points)[:, :3]
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) <= config.radius_m]
    centres = keys_to_centres(np.unique(voxel_keys(pts, config.voxel_m)), config.voxel_m)
    xy, value = encode(centres, 0.0, config)
    return render(xy, value, np.zeros((1, 3)), config)[0]
