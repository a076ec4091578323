"""A spinning multi-beam LiDAR (HDL-64E-like) ray cast into the 2.5D world raster.

Each ray walks the raster cells it crosses (a 2D DDA) and, in each cell, tests the ground, the
solid column and the floating interval against the ray's height over the cell, so the first
surface hit wins (occlusion). Porous materials (foliage, fences, hedges) let a ray through a cell
with a per-material probability. Returns get Gaussian range noise, reflectance from the material
and the incidence angle, and random dropouts that grow with range and for dark surfaces.

Random numbers inside the ray caster come from a counter-based hash of (frame key, ray, draw),
so the result does not depend on the order rays are processed in. Porosity is a fixed property
of the world (a hash of the cell and a 0.2 m height bin, `_voxel_uniform`): the same leaves
block the same rays in every scan, as static foliage does (data version 1 drew it per ray and
scan, which made vegetation flicker between frames).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from safl_bench.synth import materials as M
from safl_bench.synth.config import SynthConfig
from safl_bench.synth.world import World

_MASK53 = 1.0 / 9007199254740992.0  # 2**-53


@numba.njit(cache=True, inline="always")
def _uniform(key: np.uint64, ray: int, draw: int) -> float:
    """A uniform number in [0, 1) from a splitmix64 hash of (key, ray, draw)."""
    z = (key + np.uint64(ray) * np.uint64(0x9E3779B97F4A7C15)
         + np.uint64(draw) * np.uint64(0xD1B54A32D192ED03))
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * _MASK53


@numba.njit(cache=True, inline="always")
def _normal(key: np.uint64, ray: int, draw: int) -> float:
    u1 = _uniform(key, ray, draw)
    u2 = _uniform(key, ray, draw + 1)
    return math.sqrt(-2.0 * math.log(1.0 - u1)) * math.cos(2.0 * math.pi * u2)


#: Height of the voxels whose porosity is fixed (`_voxel_uniform`), metres.
POROUS_VOXEL_Z = 0.2


@numba.njit(cache=True, inline="always")
def _voxel_uniform(cx: int, cy: int, z: float) -> float:
    """A uniform number fixed for the raster cell (cx, cy) at height z (0.2 m bins): porous
    matter (leaves, twigs, fence boards) does not move between scans, so whether a ray gets
    through a porous cell depends on where it crosses, not on the scan."""
    iz = math.floor(z / POROUS_VOXEL_Z) + 4096
    return _uniform(np.uint64(0x5AF1B3C7), cx * 1000003 + cy, iz)


@numba.njit(cache=True, nogil=True)
def cast_scan(dirs, gain, rot, origin, cell, cells, gmat, tmat, fmat, coarse, block_shift,
              refl_mean, refl_sd, pass_prob, max_range, noise_sd, dropout, key, out):
    """Cast rays `dirs` (n,3, sensor frame, unit) from a sensor at `rot`, `origin` (world).

    Writes returns as rows (x, y, z, reflectance) in the sensor frame into `out` (n,4) and
    returns how many were written. `coarse` holds, per block of 2**block_shift cells square,
    the highest surface in it: a ray that stays above it crosses the whole block in one step.
    """
    block = 1 << block_shift
    bsize = block * cell
    ny, nx = cells.shape[0], cells.shape[1]
    ox, oy, oz = origin[0], origin[1], origin[2]
    count = 0
    inf = np.inf
    for k in range(dirs.shape[0]):
        sx, sy, sz = dirs[k, 0], dirs[k, 1], dirs[k, 2]
        dx = rot[0, 0] * sx + rot[0, 1] * sy + rot[0, 2] * sz
        dy = rot[1, 0] * sx + rot[1, 1] * sy + rot[1, 2] * sz
        dz = rot[2, 0] * sx + rot[2, 1] * sy + rot[2, 2] * sz
        hxy = math.sqrt(dx * dx + dy * dy)
        cx = math.floor(ox / cell)
        cy = math.floor(oy / cell)
        if dx > 0:
            stepx, tmaxx, tdx = 1, ((cx + 1) * cell - ox) / dx, cell / dx
        elif dx < 0:
            stepx, tmaxx, tdx = -1, (cx * cell - ox) / dx, -cell / dx
        else:
            stepx, tmaxx, tdx = 0, inf, inf
        if dy > 0:
            stepy, tmaxy, tdy = 1, ((cy + 1) * cell - oy) / dy, cell / dy
        elif dy < 0:
            stepy, tmaxy, tdy = -1, (cy * cell - oy) / dy, -cell / dy
        else:
            stepy, tmaxy, tdy = 0, inf, inf
        t_in = 0.0
        axis = -1
        hit_t = inf
        hit_m = 0
        hit_cos = 0.0
        while t_in < max_range:
            if cx < 0 or cx >= nx or cy < 0 or cy >= ny:
                break
            # skip a whole block of cells when the ray stays above everything in it
            bx, by = cx >> block_shift, cy >> block_shift  # cx, cy >= 0 here
            cmax = coarse[by, bx]
            if oz + t_in * dz > cmax:
                tbx = (((bx + 1) * bsize - ox) / dx) if dx > 0 else ((bx * bsize - ox) / dx if dx < 0 else inf)
                tby = (((by + 1) * bsize - oy) / dy) if dy > 0 else ((by * bsize - oy) / dy if dy < 0 else inf)
                t_exit = min(tbx, tby)
                if oz + t_exit * dz > cmax and t_exit > t_in:
                    if t_exit >= max_range:
                        break
                    if tbx < tby:
                        cx = (bx + 1) * block if dx > 0 else bx * block - 1
                        cy = math.floor((oy + t_exit * dy) / cell)
                        axis = 0
                    else:
                        cy = (by + 1) * block if dy > 0 else by * block - 1
                        cx = math.floor((ox + t_exit * dx) / cell)
                        axis = 1
                    t_in = t_exit
                    if stepx != 0:
                        tmaxx = ((cx + (1 if stepx > 0 else 0)) * cell - ox) / dx
                    if stepy != 0:
                        tmaxy = ((cy + (1 if stepy > 0 else 0)) * cell - oy) / dy
                    continue
            t_out = min(tmaxx, tmaxy, max_range)
            z_in = oz + t_in * dz
            z_out = oz + t_out * dz
            face = abs(dx) if axis == 0 else (abs(dy) if axis == 1 else hxy)
            gz = cells[cy, cx, 0]
            # ground (a kerb face when entering below its height)
            if z_in <= gz and t_in > 0.0:
                hit_t, hit_m, hit_cos = t_in, gmat[cy, cx], face
            elif z_out <= gz and dz < 0.0:
                hit_t, hit_m, hit_cos = (gz - oz) / dz, gmat[cy, cx], -dz
            # solid column standing on the ground
            tp = cells[cy, cx, 1]
            if tp > gz:
                t, c = inf, 0.0
                if z_in <= tp and t_in > 0.5:
                    t, c = t_in, face
                elif z_in > tp and z_out <= tp:
                    t, c = (tp - oz) / dz, -dz
                if t < hit_t:
                    m = tmat[cy, cx]
                    if pass_prob[m] <= 0.0 or _voxel_uniform(cx, cy, oz + t * dz) >= pass_prob[m]:
                        hit_t, hit_m, hit_cos = t, m, c
            # floating interval (crowns, plates)
            fl, fh = cells[cy, cx, 2], cells[cy, cx, 3]
            if fh > fl:
                t, c = inf, 0.0
                if fl <= z_in <= fh and t_in > 0.5:
                    t, c = t_in, face
                elif z_in > fh and z_out <= fh:
                    t, c = (fh - oz) / dz, -dz
                elif z_in < fl and z_out >= fl:
                    t, c = (fl - oz) / dz, dz
                if t < hit_t:
                    m = fmat[cy, cx]
                    if pass_prob[m] <= 0.0 or _voxel_uniform(cx, cy, oz + t * dz) >= pass_prob[m]:
                        hit_t, hit_m, hit_cos = t, m, c
            if hit_t < inf:
                break
            if tmaxx < tmaxy:
                cx += stepx
                t_in = tmaxx
                tmaxx += tdx
                axis = 0
            else:
                cy += stepy
                t_in = tmaxy
                tmaxy += tdy
                axis = 1
        if hit_t >= max_range or hit_t == inf:
            continue
        refl = gain[k] * refl_mean[hit_m] * (0.7 + 0.3 * hit_cos) + refl_sd[hit_m] * _normal(key, k, 0)
        refl = min(max(refl, 0.0), 1.0)
        r = hit_t + noise_sd * _normal(key, k, 2)
        p_drop = dropout + 0.35 * (r / max_range) ** 2 + (0.25 if refl < 0.04 else 0.0)
        if _uniform(key, k, 1) < p_drop or r <= 0.0:
            continue
        out[count, 0] = sx * r
        out[count, 1] = sy * r
        out[count, 2] = sz * r
        out[count, 3] = refl
        count += 1
    return count


#: The roof of the ego vehicle under the sensor (sensor frame, metres): rays that reach this
#: rectangle of the plane z = EGO_ROOF_Z are blocked, which leaves KITTI's blind spot around the
#: car (longer behind it than in front).
EGO_ROOF_Z = -0.35
EGO_ROOF_X = (-1.7, 0.6)
EGO_ROOF_Y = (-0.85, 0.85)


def ego_blocked(dirs: np.ndarray) -> np.ndarray:
    """Which sensor-frame rays hit the ego vehicle's own roof."""
    down = dirs[:, 2] < 0
    t = np.where(down, EGO_ROOF_Z / np.where(down, dirs[:, 2], -1.0), 0.0)
    x, y = t * dirs[:, 0], t * dirs[:, 1]
    return down & (x > EGO_ROOF_X[0]) & (x < EGO_ROOF_X[1]) & (y > EGO_ROOF_Y[0]) & (y < EGO_ROOF_Y[1])


class Lidar:
    """The sensor: beam geometry, per-beam gain, and one scan per pose."""

    def __init__(self, config: SynthConfig, rng: np.random.Generator) -> None:
        self.config = config
        self.elevations = np.radians(config.elevations_deg())
        self.n_azimuth = round(360.0 / config.azimuth_res_deg)
        beam_gain = rng.uniform(0.85, 1.15, size=len(self.elevations))
        self.gain = np.repeat(beam_gain, self.n_azimuth).astype(np.float64)

    def directions(self, azimuth_offset: float) -> np.ndarray:
        """Unit ray directions (beams x azimuths, 3) in the sensor frame, ring by ring."""
        az = azimuth_offset + np.arange(self.n_azimuth) * (2 * np.pi / self.n_azimuth)
        el = self.elevations[:, None]
        dirs = np.stack(
            np.broadcast_arrays(np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)), axis=-1
        )
        return np.ascontiguousarray(dirs.reshape(-1, 3))

    def scan(self, world: World, pose: np.ndarray, key: int, azimuth_offset: float) -> np.ndarray:
        """One scan (N,4) float32 in the sensor frame from world pose `pose` (4x4)."""
        cfg = self.config
        dirs = self.directions(azimuth_offset)
        free = ~ego_blocked(dirs)
        dirs = np.ascontiguousarray(dirs[free])
        out = np.empty((len(dirs), 4), dtype=np.float32)
        n = cast_scan(
            dirs, self.gain[free], np.ascontiguousarray(pose[:3, :3]), np.ascontiguousarray(pose[:3, 3]),
            float(world.cell), world.cells, world.ground_mat, world.top_mat, world.float_mat,
            world.coarse, world.block_shift, M.REFL_MEAN, M.REFL_SD, M.PASS,
            float(cfg.max_range_m), float(cfg.range_noise_m), float(cfg.dropout),
            np.uint64(key), out,
        )
        return out[:n].copy()
