"""Sliding local maps (paper II.A): the last K scans within r metres of the robot, in log-odds.

Two backends share one interface (`LocalMap`):

- `VoxelLocalMap` ("voxel", the default): a fast vectorised voxel map. Each scan is voxelised
  once (numba), and every voxel it hits gets one hit (once per scan, as OctoMap's
  `insertPointCloud` updates each voxel once per scan). A hash table holds the hit count of each
  voxel over the window; a ring buffer of the last K scans' voxel keys lets the oldest scan be
  subtracted when a new one arrives. Log-odds = min(hits * logodds(prob_hit),
  logodds(clamp_max)); a voxel is occupied when that exceeds logodds(prob_occupied).
  **Misses are ignored**: no rays are cast, so a voxel is never cleared by a later beam passing
  through it; it only leaves the map when no scan of the window hits it or when it is farther
  than r from the robot. In a static scene this matches OctoMap closely; with moving objects the
  voxel map keeps their trail for the window's length (one second by default).
- `OctoMapLocalMap` ("octomap"): the real OctoMap (octomap-python) with full ray casting, hits and
  misses. Each scan is downsampled to the voxel grid (one point per voxel centre, as OctoMap
  users do) and inserted with its sensor origin. An occupied voxel is deleted when no scan of the
  window hit it any more; all nodes farther than r from the robot are deleted every 10 scans
  (occupied ones are filtered by distance on every read).
  Free-space evidence (misses) of scans older than the window is not undone (OctoMap cannot),
  so this backend's map depends weakly on history before the window; clamping bounds that.

Both give `occupied()`: the centres (M, 3) float64 of the occupied voxels within r (ground
plane) of the latest scan's origin, in the world frame, sorted by voxel key (deterministic).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import deque

import numba
import numpy as np

from safl_bench.errors import ConfigError
from safl_bench.views.mapconfig import MapConfig, logodds

_OFF = 1 << 20  # voxel index offset: 21 bits per axis, +-2^20 voxels
_MASK = (1 << 21) - 1
_EMPTY = np.int64(-1)
OCTOMAP_TREE_DEPTH = 16
SWEEP_EVERY = 10  # the OctoMap backend deletes far nodes every this many scans


@numba.njit(cache=True)
def _scan_keys(points: np.ndarray, rot: np.ndarray, trans: np.ndarray, res: float, rmax: float) -> np.ndarray:
    """Voxel keys (world frame) of the points within rmax (sensor ground plane) of the sensor."""
    n = points.shape[0]
    out = np.empty(n, dtype=np.int64)
    m = 0
    r2 = rmax * rmax
    inv = 1.0 / res
    for i in range(n):
        x = float(points[i, 0])
        y = float(points[i, 1])
        z = float(points[i, 2])
        if x * x + y * y > r2:
            continue
        wx = rot[0, 0] * x + rot[0, 1] * y + rot[0, 2] * z + trans[0]
        wy = rot[1, 0] * x + rot[1, 1] * y + rot[1, 2] * z + trans[1]
        wz = rot[2, 0] * x + rot[2, 1] * y + rot[2, 2] * z + trans[2]
        ix = np.int64(math.floor(wx * inv)) + _OFF
        iy = np.int64(math.floor(wy * inv)) + _OFF
        iz = np.int64(math.floor(wz * inv)) + _OFF
        out[m] = (ix << 42) | (iy << 21) | iz
        m += 1
    return out[:m]


def keys_to_centres(keys: np.ndarray, res: float) -> np.ndarray:
    """Voxel centres (M, 3) float64 of packed voxel keys."""
    keys = np.asarray(keys, dtype=np.int64)
    idx = np.stack([(keys >> 42) & _MASK, (keys >> 21) & _MASK, keys & _MASK], axis=1) - _OFF
    return (idx.astype(np.float64) + 0.5) * res


def voxel_keys(points_world: np.ndarray, res: float) -> np.ndarray:
    """Packed voxel keys (N,) int64 of world-frame points (N, >=3), no cropping."""
    pts = np.ascontiguousarray(points_world[:, :3], dtype=np.float64)
    return _scan_keys(pts, np.eye(3), np.zeros(3), res, np.inf)


@numba.njit(cache=True, inline="always")
def _slot(table: np.ndarray, key: np.int64) -> int:
    mask = table.shape[0] - 1
    h = (np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(40)
    i = int(h) & mask
    while table[i] != key and table[i] != -1:
        i = (i + 1) & mask
    return i


@numba.njit(cache=True)
def _table_add(table: np.ndarray, hits: np.ndarray, stamp: np.ndarray, keys: np.ndarray, sid: int):
    """Add one hit per distinct key of a scan; return (the scan's distinct keys, new slots)."""
    out = np.empty(keys.shape[0], dtype=np.int64)
    m = 0
    claimed = 0
    for k in keys:
        i = _slot(table, k)
        if table[i] == -1:
            table[i] = k
            hits[i] = 0
            stamp[i] = -1
            claimed += 1
        if stamp[i] != sid:
            stamp[i] = sid
            hits[i] += 1
            out[m] = k
            m += 1
    return out[:m], claimed


@numba.njit(cache=True)
def _table_remove(table: np.ndarray, hits: np.ndarray, keys: np.ndarray) -> np.ndarray:
    """Take one hit off each key; return the keys whose count dropped to zero."""
    out = np.empty(keys.shape[0], dtype=np.int64)
    m = 0
    for k in keys:
        i = _slot(table, k)
        if table[i] == k:
            hits[i] -= 1
            if hits[i] == 0:
                out[m] = k
                m += 1
    return out[:m]


@numba.njit(cache=True)
def _table_collect(table, hits, min_hits, ox, oy, radius, res):
    """Keys with hits >= min_hits whose voxel centre lies within radius (plane) of (ox, oy)."""
    out = np.empty(table.shape[0], dtype=np.int64)
    m = 0
    r2 = radius * radius
    for i in range(table.shape[0]):
        k = table[i]
        if k == -1 or hits[i] < min_hits:
            continue
        cx = (float(((k >> 42) & _MASK) - _OFF) + 0.5) * res - ox
        cy = (float(((k >> 21) & _MASK) - _OFF) + 0.5) * res - oy
        if cx * cx + cy * cy <= r2:
            out[m] = k
            m += 1
    return out[:m]


@numba.njit(cache=True)
def _table_rehash(table, hits, new_table, new_hits, new_stamp):
    """Move the live entries (hits > 0) into a fresh table; return their number."""
    n = 0
    for i in range(table.shape[0]):
        if table[i] != -1 and hits[i] > 0:
            j = _slot(new_table, table[i])
            new_table[j] = table[i]
            new_hits[j] = hits[i]
            new_stamp[j] = -1
            n += 1
    return n


class HitTable:
    """Voxel key -> number of window scans that hit it (open addressing, grows and compacts)."""

    def __init__(self, capacity: int = 1 << 18) -> None:
        self._alloc(capacity)
        self.used = 0

    def _alloc(self, capacity: int) -> None:
        self.keys = np.full(capacity, _EMPTY, dtype=np.int64)
        self.hits = np.zeros(capacity, dtype=np.int32)
        self.stamp = np.full(capacity, -1, dtype=np.int64)

    def add(self, keys: np.ndarray, sid: int) -> np.ndarray:
        """One hit per distinct key (for scan id `sid`); returns the distinct keys."""
        if 2 * (self.used + len(keys)) > len(self.keys):
            self._compact(self.used + len(keys))
        distinct, claimed = _table_add(self.keys, self.hits, self.stamp, keys, sid)
        self.used += int(claimed)
        return distinct

    def remove(self, keys: np.ndarray) -> np.ndarray:
        """One hit off each key; returns the keys no scan hits any more."""
        return _table_remove(self.keys, self.hits, keys)

    def collect(self, min_hits: int, ox: float, oy: float, radius: float, res: float) -> np.ndarray:
        """Sorted keys with at least `min_hits` hits within `radius` of (ox, oy)."""
        return np.sort(_table_collect(self.keys, self.hits, min_hits, ox, oy, radius, res))

    def _compact(self, need: int) -> None:
        old_keys, old_hits = self.keys, self.hits
        live = int(np.count_nonzero(old_hits[old_keys != _EMPTY] > 0))
        capacity = len(old_keys)
        while 2 * (live + need) > capacity:
            capacity *= 2
        self._alloc(capacity)
        self.used = int(_table_rehash(old_keys, old_hits, self.keys, self.hits, self.stamp))


class LocalMap(ABC):
    """A sliding local map: insert scans in order, read the occupied voxels near the robot."""

    def __init__(self, config: MapConfig) -> None:
        self.config = config
        self.origin: np.ndarray = np.zeros(3)  # the latest scan's sensor position (world frame)
        self.count = 0  # scans inserted so far
        self._ring: deque[np.ndarray] = deque()
        self._table = HitTable()

    def _keys(self, points: np.ndarray, pose: np.ndarray) -> np.ndarray:
        points = np.asarray(points)
        if points.ndim != 2 or points.shape[1] < 3:
            raise ConfigError(f"a scan must be an (N, >=3) array, got shape {points.shape}")
        pose = np.asarray(pose, dtype=np.float64)
        return _scan_keys(
            np.ascontiguousarray(points), np.ascontiguousarray(pose[:3, :3]),
            np.ascontiguousarray(pose[:3, 3]), self.config.voxel_m, self.config.insert_radius_m,
        )

    def insert(self, points: np.ndarray, pose: np.ndarray) -> None:
        """Insert a scan (N, >=3) given in the sensor frame, with its 4x4 sensor-to-world pose."""
        keys = self._keys(points, pose)
        self.origin = np.asarray(pose, dtype=np.float64)[:3, 3].copy()
        distinct = self._table.add(keys, self.count)
        self._ring.append(distinct)
        stale = np.empty(0, dtype=np.int64)
        if len(self._ring) > self.config.window:
            stale = self._table.remove(self._ring.popleft())
        self._integrate(distinct, stale)
        self.count += 1

    def _integrate(self, distinct: np.ndarray, stale: np.ndarray) -> None:  # noqa: B027
        """Backend hook: the new scan's distinct voxels, and voxels no window scan hits now."""

    def candidate_keys(self, min_hits: int = 1) -> np.ndarray:
        """Sorted keys of voxels hit by the window's scans, within radius_m of the robot."""
        c = self.config
        return self._table.collect(min_hits, self.origin[0], self.origin[1], c.radius_m, c.voxel_m)

    @abstractmethod
    def occupied(self) -> np.ndarray:
        """Occupied voxel centres (M, 3) float64, world frame, within radius_m of the robot."""


class VoxelLocalMap(LocalMap):
    """Hits-only voxel map (see module doc): fast, numba, no ray casting."""

    @property
    def min_hits(self) -> int:
        """Fewest window hits whose log-odds (clamped) exceed the occupancy threshold."""
        c = self.config
        l_hit, l_occ, l_max = logodds(c.prob_hit), logodds(c.prob_occupied), logodds(c.clamp_max)
        if l_max <= l_occ:  # pragma: no cover - MapConfig forbids it
            raise ConfigError("clamp_max must exceed prob_occupied")
        return max(1, math.floor(l_occ / l_hit) + 1)

    def occupied(self) -> np.ndarray:
        return keys_to_centres(self.candidate_keys(self.min_hits), self.config.voxel_m)


class OctoMapLocalMap(LocalMap):
    """The real OctoMap with ray casting (see module doc); the reference backend."""

    def __init__(self, config: MapConfig) -> None:
        super().__init__(config)
        import octomap

        tree = octomap.OcTree(config.voxel_m)
        tree.setProbHit(config.prob_hit)
        tree.setProbMiss(config.prob_miss)
        tree.setClampingThresMin(config.clamp_min)
        tree.setClampingThresMax(config.clamp_max)
        tree.setOccupancyThres(config.prob_occupied)
        self.tree = tree

    def _integrate(self, distinct: np.ndarray, stale: np.ndarray) -> None:
        centres = keys_to_centres(distinct, self.config.voxel_m)
        self.tree.insertPointCloud(centres, self.origin.copy(), maxrange=-1.0)
        for centre in keys_to_centres(stale, self.config.voxel_m):
            self.tree.deleteNode(centre, OCTOMAP_TREE_DEPTH)
        if (self.count + 1) % SWEEP_EVERY == 0:
            self._drop_far()

    def _drop_far(self) -> None:
        """Delete every node (free or occupied) farther than radius_m from the robot."""
        r = self.config.radius_m
        far = []
        for it in self.tree.begin_leafs():
            x, y, _ = it.getCoordinate()
            if math.hypot(x - self.origin[0], y - self.origin[1]) > r + it.getSize():
                far.append((np.array(it.getCoordinate(), dtype=np.float64), int(it.getDepth())))
        for coord, depth in far:
            self.tree.deleteNode(coord, depth)

    def occupied(self) -> np.ndarray:
        centres = keys_to_centres(self.candidate_keys(1), self.config.voxel_m)
        if len(centres) == 0:
            return centres
        labels = self.tree.getLabels(centres)
        return centres[labels == 1]


def make_local_map(config: MapConfig) -> LocalMap:
    """The local map of `config.backend`."""
    if config.backend == "octomap":
        return OctoMapLocalMap(config)
    return VoxelLocalMap(config)
