"""M2DP (He, Wang & Zhang, IROS 2016): multiview 2-D projection signature of a point cloud.

Following the authors' MATLAB code (M2DP.m, CountVote2D.c):

1. centre the cloud and rotate it into its principal axes (PCA; x = 1st, y = 2nd component);
2. for p = 4 azimuths in linspace(-pi/2, pi/2, p) x q = 16 elevations in linspace(0, pi/2, q),
   project the points onto the plane with normal n = (cos e cos a, cos e sin a, sin e), in-plane
   axes px = the projection of the x axis, py = n x px;
3. on each plane, a polar grid of t = 16 sectors (from -pi) x l = 8 rings with radii
   (i/l)^2 * maxRho (maxRho: the farthest point from the centroid); the fraction of points per bin
   (bin index ring * t + sector) is one row of the 64 x 128 signature matrix A;
4. the descriptor is [u1; v1] of A's SVD: 64 + 128 = 192 values; distance: squared Euclidean.

Choices where the code leaves something open (documented here, not hidden):

* sign disambiguation, so the descriptor is deterministic and rotation invariant: each of the
  first two principal axes is oriented so that the third moment (skewness) of the points along it
  is >= 0, and the third axis is their cross product (a proper rotation, so mirror-image scenes
  stay distinct). MATLAB's `pca` instead makes the largest coefficient of each axis positive,
  which depends on the input frame. The SVD pair (u1, v1) is sign-flipped so that
  sum(u1) + sum(v1) >= 0 (A >= 0, so u1 and v1 can be taken non-negative, Perron-Frobenius);
* px is normalised (the MATLAB code leaves it at length sqrt(1 - (n.x)^2), which shrinks the
  projections on planes whose normal is near the x axis); the paper describes a projection;
* speed: clouds with more than `max_points` points are described from a deterministic subsample
  of `max_points` of them (seeded by the point count, independent of the coordinates, so the
  descriptor stays exactly rotation invariant); `max_points=None` uses every point. The bins are
  normalised counts, so a subsample estimates the same signature.

The binning is exact polar binning in numba (`baselines._polar`); u1 is the top eigenvector of
A A^T and v1 = A^T u1 / |A^T u1| (the same pair as the SVD's, computed more cheaply).
"""

from __future__ import annotations

import functools
import math
from typing import ClassVar

import numba
import numpy as np
from threadpoolctl import ThreadpoolController

from baselines._polar import quadrant_boundaries, sector_index_q
from safl_bench.errors import ConfigError, DataError
from safl_bench.methods.method import Method, Views, as_points, register_method

NUM_AZIMUTHS = 4  # p
NUM_ELEVATIONS = 16  # q
NUM_SECTORS = 16  # t
NUM_RINGS = 8  # l
MAX_POINTS = 8192

_controller: ThreadpoolController | None = None


def _blas() -> ThreadpoolController:
    """One controller for the process: building one scans the loaded libraries (~5 ms), too
    slow to repeat per `describe` call at batch 1."""
    global _controller
    if _controller is None:
        _controller = ThreadpoolController()
    return _controller


def pca_align(points: np.ndarray) -> np.ndarray:
    """The cloud centred and rotated into its principal axes (float64, (M, 3)); signs as above."""
    x = np.asarray(points, dtype=np.float64)
    x = x - x.mean(axis=0)
    cov = x.T @ x
    _, vecs = np.linalg.eigh(cov)  # ascending eigenvalues
    axes = vecs[:, ::-1].copy()
    proj = x @ axes[:, :2]
    skew = (proj**3).sum(axis=0)
    for k in range(2):
        if skew[k] < 0:
            axes[:, k] = -axes[:, k]
    axes[:, 2] = np.cross(axes[:, 0], axes[:, 1])
    return x @ axes


@functools.lru_cache(maxsize=8)
def projection_planes(num_azimuths: int, num_elevations: int) -> tuple[np.ndarray, np.ndarray]:
    """In-plane unit axes px, py (P, 3) of the p x q planes, azimuth-major like the MATLAB loops
    (cached; read-only)."""
    px_list, py_list = [], []
    ex = np.array([1.0, 0.0, 0.0])
    for azm in np.linspace(-np.pi / 2, np.pi / 2, num_azimuths):
        for elv in np.linspace(0.0, np.pi / 2, num_elevations):
            n = np.array([np.cos(elv) * np.cos(azm), np.cos(elv) * np.sin(azm), np.sin(elv)])
            px = ex - (ex @ n) * n
            norm = np.linalg.norm(px)
            if norm < 1e-12:  # normal along x (only with an azimuth of 0): take the y axis
                px = np.array([0.0, 1.0, 0.0]) - n[1] * n
                norm = np.linalg.norm(px)
            px /= norm
            px_list.append(px)
            py_list.append(np.cross(n, px))
    px_all, py_all = np.array(px_list), np.array(py_list)
    px_all.flags.writeable = False
    py_all.flags.writeable = False
    return px_all, py_all


@numba.njit(cache=True, fastmath=True, parallel=True)
def _plane_bins(
    data: np.ndarray, px: np.ndarray, py: np.ndarray, max_rho: float, num_rings: int,
    num_sectors: int, cq: np.ndarray, sq: np.ndarray, out: np.ndarray,
) -> None:
    """Counts of the projected points per (ring * num_sectors + sector) bin, one row per plane.

    Sector k covers atan2(v, u) in [-pi + k w, -pi + (k + 1) w), i.e. the angle of (-u, -v)
    from 0, found exactly as in `baselines._polar.sector_index_q` (inlined and unrolled
    for the default 16 sectors so that the loop vectorises). Planes run in parallel."""
    n = data.shape[0]
    m = num_sectors // 4
    inv_rho = 1.0 / max_rho
    xs = data[:, 0].copy()
    ys = data[:, 1].copy()
    zs = data[:, 2].copy()
    c1, c2, c3 = (cq[0], cq[1], cq[2]) if m == 4 else (0.0, 0.0, 0.0)
    s1, s2, s3 = (sq[0], sq[1], sq[2]) if m == 4 else (0.0, 0.0, 0.0)
    for k in numba.prange(px.shape[0]):
        index = np.empty(n, dtype=np.int32)
        a0, a1, a2 = px[k, 0], px[k, 1], px[k, 2]
        b0, b1, b2 = py[k, 0], py[k, 1], py[k, 2]
        if m == 4:
            for i in range(n):
                u = a0 * xs[i] + a1 * ys[i] + a2 * zs[i]
                v = b0 * xs[i] + b1 * ys[i] + b2 * zs[i]
                ring = min(int(num_rings * math.sqrt(math.sqrt(u * u + v * v) * inv_rho)), num_rings - 1)
                xx = -u
                yy = -v
                lower = (yy < 0.0) | ((yy == 0.0) & (xx < 0.0))
                xx = -xx if lower else xx
                yy = -yy if lower else yy
                quad = (xx <= 0.0) & (yy > 0.0)
                t = xx
                xx = yy if quad else xx
                yy = -t if quad else yy
                sec = (
                    8 * np.int32(lower) + 4 * np.int32(quad)
                    + np.int32(c1 * yy - s1 * xx >= 0.0)
                    + np.int32(c2 * yy - s2 * xx >= 0.0)
                    + np.int32(c3 * yy - s3 * xx >= 0.0)
                )
                index[i] = ring * 16 + sec
        else:
            for i in range(n):
                u = a0 * xs[i] + a1 * ys[i] + a2 * zs[i]
                v = b0 * xs[i] + b1 * ys[i] + b2 * zs[i]
                ring = min(int(num_rings * math.sqrt(math.sqrt(u * u + v * v) * inv_rho)), num_rings - 1)
                index[i] = ring * num_sectors + sector_index_q(-v, -u, num_sectors, cq, sq)
        row = out[k]
        for i in range(n):
            row[index[i]] += 1.0


def signature_matrix(
    points: np.ndarray,
    *,
    num_azimuths: int = NUM_AZIMUTHS,
    num_elevations: int = NUM_ELEVATIONS,
    num_sectors: int = NUM_SECTORS,
    num_rings: int = NUM_RINGS,
) -> np.ndarray:
    """M2DP's signature matrix A (p*q, l*t) float64 of an (M, 3) cloud (all points used)."""
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise DataError(f"m2dp: expected points of shape (M, 3), got {pts.shape}")
    if num_sectors % 4:
        raise ConfigError(f"m2dp: num_sectors must be a multiple of 4, got {num_sectors}")
    out = np.zeros((num_azimuths * num_elevations, num_rings * num_sectors))
    if pts.shape[0] == 0:
        return out
    data = np.ascontiguousarray(pca_align(pts))
    max_rho = float(np.sqrt((data * data).sum(axis=1).max()))
    px, py = projection_planes(num_azimuths, num_elevations)
    cq, sq = quadrant_boundaries(num_sectors)
    _plane_bins(data, px, py, max_rho if max_rho > 0 else 1.0, num_rings, num_sectors, cq, sq, out)
    out /= pts.shape[0]
    return out


def subsample(points: np.ndarray, max_points: int | None) -> np.ndarray:
    """At most `max_points` of the points, chosen by a generator seeded with the point count
    (deterministic, independent of the coordinates); all points when None or few enough."""
    m = len(points)
    if max_points is None or m <= max_points:
        return points
    keep = np.sort(np.random.default_rng(m).choice(m, size=max_points, replace=False))
    return points[keep]


def m2dp(
    points: np.ndarray,
    *,
    num_azimuths: int = NUM_AZIMUTHS,
    num_elevations: int = NUM_ELEVATIONS,
    num_sectors: int = NUM_SECTORS,
    num_rings: int = NUM_RINGS,
    max_points: int | None = MAX_POINTS,
) -> np.ndarray:
    """The M2DP descriptor [u1; v1] of one cloud (M, 3): (p*q + l*t,) float32 (192 by default).
    An empty cloud gives zeros."""
    pts = subsample(np.asarray(points), max_points)
    a = signature_matrix(
        pts, num_azimuths=num_azimuths, num_elevations=num_elevations,
        num_sectors=num_sectors, num_rings=num_rings,
    )
    if not a.any():
        return np.zeros(a.shape[0] + a.shape[1], dtype=np.float32)
    # top singular pair via the (p*q x p*q) Gram matrix: cheaper than a full SVD of A
    _, vecs = np.linalg.eigh(a @ a.T)
    u1 = vecs[:, -1]
    v1 = a.T @ u1
    v1 /= np.linalg.norm(v1)
    if u1.sum() + v1.sum() < 0:
        u1, v1 = -u1, -v1
    return np.concatenate([u1, v1]).astype(np.float32)


@register_method
class M2DP(Method):
    """M2DP (He et al. 2016): PCA-aligned multiview 2-D projections, 192-d SVD signature."""

    name: ClassVar[str] = "m2dp"
    version: ClassVar[str] = "1"
    input_kind: ClassVar[str] = "points"

    def __init__(
        self,
        num_azimuths: int = NUM_AZIMUTHS,
        num_elevations: int = NUM_ELEVATIONS,
        num_sectors: int = NUM_SECTORS,
        num_rings: int = NUM_RINGS,
        max_points: int | None = MAX_POINTS,
    ) -> None:
        self.num_azimuths = num_azimuths
        self.num_elevations = num_elevations
        self.num_sectors = num_sectors
        self.num_rings = num_rings
        self.max_points = max_points

    def describe(self, maps: Views) -> np.ndarray:
        """(N, p*q + l*t) float32 descriptors; compare with the default squared Euclidean."""
        counts = (self.num_azimuths, self.num_elevations, self.num_sectors, self.num_rings)
        if min(int(c) for c in counts) < 1 or int(self.num_sectors) % 4:
            raise ConfigError(
                f"m2dp: plane and bin counts must be >= 1 and num_sectors a multiple of 4, got {counts}"
            )
        if self.max_points is not None and int(self.max_points) < 3:
            raise ConfigError(f"m2dp: max_points must be None or >= 3, got {self.max_points}")
        views = as_points(maps)
        width = self.num_azimuths * self.num_elevations + self.num_rings * self.num_sectors
        out = np.empty((len(views), width), dtype=np.float32)
        # the per-scan BLAS/LAPACK calls are tiny; multi-threaded BLAS only adds spin-waits
        # (5x slower on a busy 2-core machine), so they run on one thread
        with _blas().limit(limits=1, user_api="blas"):
            for i, pts in enumerate(views):
                out[i] = m2dp(
                    pts, num_azimuths=self.num_azimuths, num_elevations=self.num_elevations,
                    num_sectors=self.num_sectors, num_rings=self.num_rings, max_points=self.max_points,
                )
        return out
