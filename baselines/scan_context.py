"""Scan Context (Kim & Kim, IROS 2018): a polar max-height grid with a rotation-invariant distance.

Descriptor. The points (viewpoint frame: x forward, y left, z up, origin at the sensor) are binned
on a polar grid of `num_rings` rings (equal width, out to `max_radius`) x `num_sectors` sectors
(sector 0 starts at the +x axis and sectors run counter-clockwise, like the original's
``xy2theta``). Each bin holds the maximum of ``z + sensor_height`` (the original adds
LIDAR_HEIGHT = 2.0 to make heights non-negative; we add the sensor's own height, 1.73 m on KITTI)
over its points; empty bins, and bins whose points all lie below the ground plane, hold 0. Points
beyond `max_radius` are ignored.

Ring key. The mean of each ring: a rotation-invariant (num_rings,) vector for a fast k-d-tree
candidate search (`ring_key_candidates`), as the original does before the exact distance.

Distance. Columns (sectors) are compared by cosine similarity; for a column shift s, the
similarity is the mean cosine over the columns that are non-zero in both descriptors, and the
distance is ``1 - max_s similarity`` (0 when no column is non-zero in both for any shift). It is
invariant to a heading change of the viewpoint, and the best shift gives that change
(`align`, `shift_to_heading`). Shift convention: shift s means ``query ~ np.roll(db, s, axis=1)``
(query column j is compared with database column j - s).

`distance_matrix` computes this for all Nq x Ndb pairs and all shifts at once: with per-column
unit-normalised descriptors, the summed cosine for every shift is a circular cross-correlation
along the sector axis summed over rings, i.e. per frequency of an rfft along sectors one complex
(Nq x R) @ (R x Ndb) product, then one inverse rfft. The number of columns non-zero in both is
``S - empty_q - empty_db + (columns empty in both at shift s)``; the last term is nonzero only for
pairs where both have empty columns and is counted there with bit masks. A numba kernel takes the
maximum over shifts. Work is done in query chunks so the temporaries stay bounded.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numba
import numpy as np
import scipy.fft
from scipy.spatial import cKDTree

from baselines._polar import boundary_vectors, sector_index
from safl_bench.errors import ConfigError, DataError
from safl_bench.methods.method import Method, Views, as_points, register_method

NUM_RINGS = 20
NUM_SECTORS = 60
MAX_RADIUS = 80.0
SENSOR_HEIGHT = 1.73  # KITTI's HDL-64E sits ~1.73 m above the ground
#: Bytes of temporaries per (query, database) pair and chunk of the matrix computation (approx).
_BYTES_PER_PAIR = 1100


# -- descriptor ------------------------------------------------------------------------------------
@numba.njit(cache=True, fastmath=True)
def _bin_index_kernel(
    points: np.ndarray, num_rings: int, num_sectors: int, max_radius: float,
    cos_b: np.ndarray, sin_b: np.ndarray, out: np.ndarray,
) -> None:
    """Flat bin index ring * S + sector of every point, -1 beyond `max_radius` (vectorisable)."""
    r2max = max_radius * max_radius
    scale = num_rings / max_radius
    for i in range(points.shape[0]):
        x = np.float64(points[i, 0])
        y = np.float64(points[i, 1])
        r2 = x * x + y * y
        ring = min(int(math.sqrt(r2) * scale), num_rings - 1)
        sector = sector_index(y, x, 0.0, num_sectors, cos_b, sin_b)
        out[i] = ring * num_sectors + sector if r2 <= r2max else -1


@numba.njit(cache=True)
def _max_height_kernel(points: np.ndarray, index: np.ndarray, sensor_height: float, out: np.ndarray) -> None:
    """out[bin] = max(out[bin], z + sensor_height) over the points in range."""
    for i in range(points.shape[0]):
        j = index[i]
        if j >= 0:
            h = np.float64(points[i, 2]) + sensor_height
            if h > out[j]:
                out[j] = h


def scan_context(
    points: np.ndarray,
    *,
    num_rings: int = NUM_RINGS,
    num_sectors: int = NUM_SECTORS,
    max_radius: float = MAX_RADIUS,
    sensor_height: float = SENSOR_HEIGHT,
) -> np.ndarray:
    """The Scan Context of one point cloud (M, 3): (num_rings, num_sectors) float32, >= 0."""
    pts = np.ascontiguousarray(points, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise DataError(f"scan_context: expected points of shape (M, 3), got {pts.shape}")
    cos_b, sin_b = boundary_vectors(num_sectors, 0.0)
    index = np.empty(pts.shape[0], dtype=np.int32)
    _bin_index_kernel(pts, int(num_rings), int(num_sectors), float(max_radius), cos_b, sin_b, index)
    out = np.zeros(num_rings * num_sectors, dtype=np.float64)
    _max_height_kernel(pts, index, float(sensor_height), out)
    return out.reshape(num_rings, num_sectors).astype(np.float32)


def ring_key(descriptors: np.ndarray) -> np.ndarray:
    """Ring keys: the mean of each ring over sectors; (..., R, S) -> (..., R) float32."""
    return np.asarray(descriptors, dtype=np.float32).mean(axis=-1)


def ring_key_candidates(queries: np.ndarray, database: np.ndarray, k: int = 10) -> np.ndarray:
    """Indices (Nq, k) of the k database descriptors whose ring keys are nearest (Euclidean,
    k-d tree) to each query's, nearest first; k is capped at Ndb. Inputs: (N, R, S) descriptors."""
    db_keys = ring_key(database)
    q_keys = ring_key(queries)
    if db_keys.shape[0] == 0:
        raise DataError("ring_key_candidates: the database is empty")
    k = max(1, min(int(k), db_keys.shape[0]))
    _, idx = cKDTree(db_keys).query(q_keys, k=k)
    return np.asarray(idx, dtype=np.int64).reshape(q_keys.shape[0], k)


# -- distance --------------------------------------------------------------------------------------
def _unit_columns(desc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column-normalised descriptors (N, R, S) float64 and the non-zero-column mask (N, S)."""
    d = np.asarray(desc, dtype=np.float64)
    norms = np.sqrt((d * d).sum(axis=1))
    mask = norms > 0
    unit = np.divide(d, norms[:, None, :], out=np.zeros_like(d), where=mask[:, None, :])
    return unit, mask


def align(query: np.ndarray, database: np.ndarray) -> tuple[float, int]:
    """Distance and best column shift between two descriptors (R, S).

    Returns ``(distance, shift)`` with ``query ~ np.roll(database, shift, axis=1)``; ties go to
    the smallest shift. `shift_to_heading` turns the shift into the heading change."""
    q = np.asarray(query)
    d = np.asarray(database)
    if q.ndim != 2 or q.shape != d.shape:
        raise DataError(f"align: expected two descriptors of the same shape (R, S), got {q.shape} and {d.shape}")
    qn, qm = _unit_columns(q[None])
    dn, dm = _unit_columns(d[None])
    s_count = q.shape[1]
    shifts = np.arange(s_count)
    idx = (np.arange(s_count)[None, :] - shifts[:, None]) % s_count  # (shift, column j) -> j - s
    score = np.einsum("rj,srj->s", qn[0], dn[0][:, idx].transpose(1, 0, 2))
    count = (qm[0][None, :] & dm[0][idx]).sum(axis=1)
    sim = np.divide(score, count, out=np.zeros_like(score), where=count > 0)
    best = int(np.argmax(sim))
    return float(max(0.0, 1.0 - sim[best])), best


def shift_to_heading(shift: int | np.ndarray, num_sectors: int = NUM_SECTORS) -> Any:
    """Heading change (query minus database, radians, wrapped to [-pi, pi)) of a column shift.

    A scene seen from a viewpoint turned by +a (counter-clockwise) appears rotated by -a, i.e.
    shifted by -a / sector width; hence heading = -shift * 2 pi / S."""
    width = 2.0 * np.pi / num_sectors
    heading = -np.asarray(shift, dtype=np.float64) * width
    return (heading + np.pi) % (2.0 * np.pi) - np.pi


def _popcount64(x: Any) -> Any:
    x = x - ((x >> np.uint64(1)) & np.uint64(0x5555555555555555))
    x = (x & np.uint64(0x3333333333333333)) + ((x >> np.uint64(2)) & np.uint64(0x3333333333333333))
    x = (x + (x >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return (x * np.uint64(0x0101010101010101)) >> np.uint64(56)


_popcount64_nb = numba.njit(cache=True, inline="always")(_popcount64)


def _pack_bits(mask: np.ndarray) -> np.ndarray:
    """(N, S) bool -> (N, ceil(S/64)) uint64 bit masks."""
    n, s = mask.shape
    words = (s + 63) // 64
    padded = np.zeros((n, words * 64), dtype=np.uint64)
    padded[:, :s] = mask
    weights = np.uint64(1) << np.arange(64, dtype=np.uint64)
    return (padded.reshape(n, words, 64) * weights).sum(axis=2, dtype=np.uint64)


@numba.njit(cache=True)
def _best_shift_kernel(
    score: np.ndarray, empty_q: np.ndarray, bits_q: np.ndarray, empty_d: np.ndarray,
    bits_d_rot: np.ndarray, out_dist: np.ndarray, out_shift: np.ndarray,
) -> None:
    """score (S, c, Ndb): summed cosines per shift. Writes 1 - max_s score/count and argmax."""
    num_shifts, c, ndb = score.shape
    words = bits_q.shape[1]
    best = np.empty(ndb, dtype=np.float32)
    arg = np.empty(ndb, dtype=np.int32)
    for a in range(c):
        # pairs whose count does not depend on the shift: the max of the raw score decides
        best[:] = score[0, a]
        arg[:] = 0
        for s in range(1, num_shifts):
            row = score[s, a]
            for b in range(ndb):
                v = row[b]
                take = v > best[b]
                best[b] = v if take else best[b]
                arg[b] = s if take else arg[b]
        for b in range(ndb):
            base = num_shifts - empty_q[a] - empty_d[b]
            if empty_q[a] == 0 or empty_d[b] == 0:
                sim = best[b] / base if base > 0 else 0.0
                shift = arg[b] if base > 0 else 0
            else:  # both have empty columns: the count depends on the shift
                sim = -np.inf
                shift = 0
                for s in range(num_shifts):
                    both_empty = 0
                    for w in range(words):
                        both_empty += _popcount64_nb(bits_q[a, w] & bits_d_rot[b, s, w])
                    count = base + both_empty
                    val = score[s, a, b] / count if count > 0 else 0.0
                    if val > sim:
                        sim = val
                        shift = s
            out_dist[a, b] = max(0.0, 1.0 - sim)
            out_shift[a, b] = shift


def _as_batch(desc: np.ndarray, what: str) -> np.ndarray:
    d = np.asarray(desc)
    if d.ndim != 3 or d.shape[0] == 0:
        raise DataError(f"{what}: expected Scan Context descriptors of shape (N, R, S) with N > 0, got {d.shape}")
    if not np.isfinite(d).all():
        raise DataError(f"{what}: descriptors contain NaN or inf")
    return d


def distance_matrix(
    queries: np.ndarray,
    database: np.ndarray,
    *,
    return_shift: bool = False,
    max_bytes: int = 1 << 28,
) -> Any:
    """Scan Context distances (Nq, Ndb) float32 for descriptors (Nq, R, S) and (Ndb, R, S).

    With `return_shift`, also the best shifts (Nq, Ndb) int16 (convention as in `align`).
    `max_bytes` bounds the temporaries (the query chunk size follows from it)."""
    q = _as_batch(queries, "query")
    d = _as_batch(database, "database")
    if q.shape[1:] != d.shape[1:]:
        raise DataError(f"query and database descriptors differ in shape: {q.shape[1:]} vs {d.shape[1:]}")
    nq, ndb = q.shape[0], d.shape[0]
    num_sectors = q.shape[2]
    qn, qmask = _unit_columns(q)
    dn, dmask = _unit_columns(d)
    # spectra along sectors; irfft(Xq * conj(Xd))[s] = sum_j q[j] d[j - s]  (query ~ roll(db, s))
    xq = scipy.fft.rfft(qn.astype(np.float32), axis=2)  # (Nq, R, F)
    xd = scipy.fft.rfft(dn.astype(np.float32), axis=2)  # (Ndb, R, F)
    xq_f = np.ascontiguousarray(xq.transpose(2, 0, 1))  # (F, Nq, R)
    xd_f = np.ascontiguousarray(np.conj(xd).transpose(2, 1, 0))  # (F, R, Ndb)
    empty_q = (~qmask).sum(axis=1).astype(np.int64)
    empty_d = (~dmask).sum(axis=1).astype(np.int64)
    bits_q = _pack_bits(~qmask)
    # database empty-column masks rotated by every shift: column j of shift s is db column j - s
    rot_idx = (np.arange(num_sectors)[None, :] - np.arange(num_sectors)[:, None]) % num_sectors
    bits_d_rot = np.ascontiguousarray(
        _pack_bits((~dmask)[:, rot_idx].reshape(ndb * num_sectors, num_sectors)).reshape(ndb, num_sectors, -1)
    )
    dist = np.empty((nq, ndb), dtype=np.float32)
    shift = np.empty((nq, ndb), dtype=np.int16)
    chunk = max(1, int(max_bytes // (_BYTES_PER_PAIR * ndb)))
    for lo in range(0, nq, chunk):
        hi = min(nq, lo + chunk)
        spec = np.matmul(xq_f[:, lo:hi], xd_f)  # (F, c, Ndb) complex64
        score = scipy.fft.irfft(spec, n=num_sectors, axis=0, workers=-1)  # (S, c, Ndb) float32
        del spec
        _best_shift_kernel(score, empty_q[lo:hi], bits_q[lo:hi], empty_d, bits_d_rot, dist[lo:hi], shift[lo:hi])
        del score
    return (dist, shift) if return_shift else dist


# -- the plug-in -----------------------------------------------------------------------------------
@register_method
class ScanContext(Method):
    """Scan Context (Kim & Kim 2018): polar max-height grid, column-shift cosine distance."""

    name: ClassVar[str] = "scan_context"
    version: ClassVar[str] = "1"
    input_kind: ClassVar[str] = "points"
    runtime_params: ClassVar[tuple[str, ...]] = ("max_bytes",)

    def __init__(
        self,
        num_rings: int = NUM_RINGS,
        num_sectors: int = NUM_SECTORS,
        max_radius: float = MAX_RADIUS,
        sensor_height: float = SENSOR_HEIGHT,
        max_bytes: int = 1 << 28,
    ) -> None:
        self.num_rings = num_rings
        self.num_sectors = num_sectors
        self.max_radius = max_radius
        self.sensor_height = sensor_height
        self.max_bytes = max_bytes

    def _check(self) -> None:
        if int(self.num_rings) < 1 or int(self.num_sectors) < 2:
            raise ConfigError(f"scan_context: need num_rings >= 1 and num_sectors >= 2, got {self.num_rings}, {self.num_sectors}")
        if not float(self.max_radius) > 0:
            raise ConfigError(f"scan_context: max_radius must be > 0, got {self.max_radius}")
        if int(self.max_bytes) < 1:
            raise ConfigError(f"scan_context: max_bytes must be >= 1, got {self.max_bytes}")

    def describe(self, maps: Views) -> np.ndarray:
        """(N, num_rings * num_sectors) float32: the flattened (ring-major) Scan Contexts."""
        self._check()
        views = as_points(maps)
        out = np.empty((len(views), self.num_rings * self.num_sectors), dtype=np.float32)
        for i, pts in enumerate(views):
            out[i] = scan_context(
                pts, num_rings=self.num_rings, num_sectors=self.num_sectors,
                max_radius=self.max_radius, sensor_height=self.sensor_height,
            ).ravel()
        return out

    def _grids(self, desc: np.ndarray, what: str) -> np.ndarray:
        d = np.asarray(desc)
        width = self.num_rings * self.num_sectors
        if d.ndim != 2 or d.shape[1] != width:
            raise DataError(f"{what} descriptors: expected shape (N, {width}) from scan_context.describe, got {d.shape}")
        return d.reshape(d.shape[0], self.num_rings, self.num_sectors)

    def distance(self, queries: np.ndarray, database: np.ndarray) -> np.ndarray:
        """(Nq, Ndb) float32: 1 - best column-shift mean cosine similarity (0 = identical)."""
        self._check()
        return distance_matrix(
            self._grids(queries, "query"), self._grids(database, "database"), max_bytes=int(self.max_bytes)
        )

    def distance_and_shift(self, queries: np.ndarray, database: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distances and best shifts (see `align` for the convention; `heading` converts them)."""
        self._check()
        dist, shift = distance_matrix(
            self._grids(queries, "query"), self._grids(database, "database"),
            return_shift=True, max_bytes=int(self.max_bytes),
        )
        return dist, shift

    def heading(self, shift: np.ndarray) -> np.ndarray:
        """Heading change (query minus database, rad) for shifts from `distance_and_shift`."""
        return np.asarray(shift_to_heading(shift, self.num_sectors))

    def candidates(self, queries: np.ndarray, database: np.ndarray, k: int = 10) -> np.ndarray:
        """(Nq, k) database indices nearest by ring key (the original's fast pre-selection)."""
        return ring_key_candidates(self._grids(queries, "query"), self._grids(database, "database"), k)
