"""Synthetic local-map point clouds for the classic-descriptor tests and benchmarks.

A ground plane at z = -sensor height, box buildings (their four walls), and poles, sampled on a
0.3 m lattice like occupied voxel centres, in the viewpoint frame (x forward, y left, z up).
"""

from __future__ import annotations

import numpy as np

SENSOR_HEIGHT = 1.73
STEP = 0.3


def _wall(p0: np.ndarray, p1: np.ndarray, height: float, ground: float) -> np.ndarray:
    length = float(np.linalg.norm(p1 - p0))
    n_along = max(2, int(length / STEP))
    n_up = max(2, int(height / STEP))
    t = np.linspace(0.0, 1.0, n_along)
    xy = p0[None, :] + t[:, None] * (p1 - p0)[None, :]
    z = ground + np.linspace(0.0, height, n_up)
    xyz = np.empty((n_along, n_up, 3))
    xyz[:, :, :2] = xy[:, None, :]
    xyz[:, :, 2] = z[None, :]
    return xyz.reshape(-1, 3)


def scene(seed: int, *, radius: float = 50.0, n_boxes: int = 12, n_poles: int = 25) -> np.ndarray:
    """One synthetic local map (M, 3) float32, M ~ 40k-90k; different seeds, different places."""
    rng = np.random.default_rng(seed)
    ground = -SENSOR_HEIGHT
    g = np.arange(-radius, radius, STEP * 1.5)
    gx, gy = np.meshgrid(g, g, indexing="ij")
    keep = gx**2 + gy**2 < radius**2
    gz = ground + 0.03 * rng.standard_normal(keep.sum())
    parts = [np.column_stack([gx[keep], gy[keep], gz])]
    for _ in range(n_boxes):
        centre = rng.uniform(-radius * 0.8, radius * 0.8, 2)
        if np.linalg.norm(centre) < 8.0:
            centre *= 8.0 / max(np.linalg.norm(centre), 1e-3)
        w, d = rng.uniform(4.0, 14.0, 2)
        yaw = rng.uniform(0, np.pi)
        height = rng.uniform(3.0, 15.0)
        c, s = np.cos(yaw), np.sin(yaw)
        corners = (
            np.array([[-w, -d], [w, -d], [w, d], [-w, d]]) / 2 @ np.array([[c, s], [-s, c]])
            + centre
        )
        for k in range(4):
            parts.append(_wall(corners[k], corners[(k + 1) % 4], height, ground))
    for _ in range(n_poles):
        xy = rng.uniform(-radius * 0.9, radius * 0.9, 2)
        height = rng.uniform(2.0, 8.0)
        z = ground + np.arange(0.0, height, STEP)
        parts.append(np.column_stack([np.full_like(z, xy[0]), np.full_like(z, xy[1]), z]))
    pts = np.concatenate(parts)
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) < radius]
    return pts.astype(np.float32)


def rotate_z(points: np.ndarray, angle: float) -> np.ndarray:
    """The points rotated counter-clockwise by `angle` rad about the vertical axis (float64 math)."""
    c, s = np.cos(angle), np.sin(angle)
    p = points.astype(np.float64)
    out = p.copy()
    out[:, 0] = c * p[:, 0] - s * p[:, 1]
    out[:, 1] = s * p[:, 0] + c * p[:, 1]
    return out.astype(np.float32)
