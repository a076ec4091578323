"""Town generation: a 2.5D raster of the synthetic world, ready for ray casting.

Each raster cell holds a ground height and material, a solid column standing on the ground
(buildings, walls, fences, hedges, car bodies, trunks, poles) and one floating interval
(tree crowns, sign plates, lamp arms). The town is drawn as axis-aligned shapes in the plan
frame of the street grid (see `streets`), then resampled into the world frame through the warp,
which bends streets and blocks alike.

Blocks come from a small palette (urban rows, detached houses, parks, open fields, parking
lots) with repeated building heights and house shapes, so different places can look alike,
as in a real town.

Data version 2 added what real KITTI streets have 4-15 m from the sensor and version 1 lacked
(measured with `safl-bench data fidelity` against BEVPlace's images of KITTI 00 and 02: 2.5 %
non-zero pixels against 6.3-7.4 %): bushes and hedges along most street edges, bay windows,
pillars and steps on facades, hedged front gardens with bushes, rough grass and cars in
driveways, tall grass in parks and open fields, more parked cars, lower tree crowns, and
ground rising inside parks, open fields and gardens (`TERRAIN`: embankments and raised gardens,
whose far parts rise above the BEV-density encoding's ground cut as real KITTI's do); porosity
became a fixed property of the world (`safl_bench.synth.lidar`), and the whole town lies on
rolling land (`safl_bench.synth.terrain`) that the vehicle follows.

Data version 5 changed two things the BEV-density images of real KITTI show and the synthetic
ones lacked: parked cars fill their footprint there (the beams pass the windows and return from
the seats and the far side), and the roadside is occupied 8-12 m out (13-27 % of the pixels
against 4 %), where front yards lie before the houses. So a car's cabin is porous glass
(`materials.GLASS`) above a body whose top is shaped (`CAR_PROFILE`: bonnet and boot below the
roof), and urban blocks set their buildings back (`URBAN_SETBACKS_M`) behind front yards of
rough grass, bushes and low boundaries (`front_yard`, from its own random stream, so the rest
of a seed's town is that of version 4). On sequence 00 of the towns of seeds 0-4 the non-zero
share rose on every town (mean 5.5 -> 6.1 %, real 6.3-7.4 %) and the SAD curve's excess over the
real envelope moved from a mean of 0.025 to 0.022 (`safl-bench data fidelity --seed N`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from safl_bench.synth import materials as M
from safl_bench.synth.streets import StreetGrid

SIDEWALK_Z = 0.12  # kerb height: everything but the carriageway is raised by this much
LANE_OFFSET_M = 1.6  # driving lane centre, right of the street centre line
#: Ground rising inside a block of these kinds (with probability `TERRAIN_P`): (slope),
#: (flat margin m), (highest rise m), each drawn uniformly in its range; streets, urban blocks
#: and parking lots stay flat.
TERRAIN: dict[str, tuple[tuple[float, float], tuple[float, float], tuple[float, float]]] = {
    "residential": ((0.03, 0.08), (0.5, 2.0), (0.5, 1.5)),
    "park": ((0.03, 0.12), (0.0, 3.0), (0.8, 3.0)),
    "open": ((0.03, 0.15), (0.0, 3.0), (1.0, 4.0)),
}
TERRAIN_P = 0.85
#: Setbacks of the buildings of an urban block from its edge (one per block, equally likely);
#: set back 2 m or more, a building has a front yard (`front_yard`).
URBAN_SETBACKS_M = (0.0, 0.0, 2.0, 3.5, 5.0)
#: Share of street sides (between two crossings) with cars parked along the kerb.
PARKING_P = 0.9


@dataclass
class World:
    """The world raster: cell (iy, ix) covers [ix*cell, (ix+1)*cell) x [iy*cell, (iy+1)*cell)."""

    cell: float
    ground: np.ndarray  # (ny, nx) float32 ground height
    ground_mat: np.ndarray  # (ny, nx) uint8
    top: np.ndarray  # (ny, nx) float32 top of the solid column (solid where top > ground)
    top_mat: np.ndarray  # (ny, nx) uint8
    lo: np.ndarray  # (ny, nx) float32 floating interval [lo, hi] (empty where hi <= lo)
    hi: np.ndarray
    float_mat: np.ndarray  # (ny, nx) uint8
    grid: StreetGrid
    #: per block x block cells, the highest surface in them (lets rays skip empty space)
    coarse: np.ndarray = dataclasses.field(init=False)
    #: (ny, nx, 4) float32 ground, top, lo, hi side by side: one cache line per cell for rays
    cells: np.ndarray = dataclasses.field(init=False)
    block_shift: int = 3  # blocks of 8 x 8 cells

    def __post_init__(self) -> None:
        occ = np.maximum(self.ground, np.where(self.top > self.ground, self.top, -np.inf))
        occ = np.maximum(occ, np.where(self.hi > self.lo, self.hi, -np.inf)).astype(np.float32)
        b = 1 << self.block_shift
        ny, nx = occ.shape
        pad = np.full((-(-ny // b) * b, -(-nx // b) * b), -np.inf, dtype=np.float32)
        pad[:ny, :nx] = occ
        self.coarse = pad.reshape(pad.shape[0] // b, b, pad.shape[1] // b, b).max(axis=(1, 3))
        self.cells = np.stack([self.ground, self.top, self.lo, self.hi], axis=-1)

    @property
    def shape(self) -> tuple[int, int]:
        return self.ground.shape


def _span(ab: tuple[float, float]) -> tuple[float, float]:
    """The two ends of a range in increasing order."""
    a, b = ab
    return (a, b) if a <= b else (b, a)


#: A car's height profile along its length: (position, share of the way from the body's height
#: to the roof's) at the knots, positions as shares of the cabin's half length from its centre
#: (+ towards the front); the hood and boot lie beyond the cabin and drop towards the bumpers.
CAR_PROFILE = ((-1.0, 0.0), (-0.75, 1.0), (0.45, 1.0), (1.0, 0.0))
_CAR_KNOTS, _CAR_SHARES = (list(v) for v in zip(*CAR_PROFILE, strict=True))


def _car_height(t: float, cabin: float, body: float, roof: float) -> float:
    """Height of a car's top at `t` (share of its length from the cabin's centre, + towards the
    front) for a cabin taking `cabin` of the length, a body `body` high and a roof `roof` high."""
    half = cabin / 2
    if abs(t) <= half:
        x = t / half
        share = float(np.interp(x, _CAR_KNOTS, _CAR_SHARES))
        return body + share * (roof - body)
    beyond = min((abs(t) - half) / max(0.5 - half, 1e-6), 1.0)  # 0 at the cabin, 1 at the bumper
    drop = 0.25 if t > 0 else 0.15  # the hood slopes more than the boot
    return body - drop * beyond


class _Plan:
    """The town drawn in the plan frame (u along columns, v along rows)."""

    def __init__(self, size_u: float, size_v: float, cell: float) -> None:
        self.c = cell
        self.nu = int(np.ceil(size_u / cell))
        self.nv = int(np.ceil(size_v / cell))
        shape = (self.nv, self.nu)
        self.g = np.full(shape, SIDEWALK_Z, dtype=np.float32)
        self.gm = np.full(shape, M.GRASS, dtype=np.uint8)
        self.top = np.zeros(shape, dtype=np.float32)
        self.tm = np.zeros(shape, dtype=np.uint8)
        self.lo = np.zeros(shape, dtype=np.float32)
        self.hi = np.zeros(shape, dtype=np.float32)
        self.fm = np.zeros(shape, dtype=np.uint8)

    def _sl(self, u0: float, u1: float, v0: float, v1: float) -> tuple[slice, slice]:
        c = self.c
        iu0, iu1 = sorted((round(u0 / c), round(u1 / c)))
        iv0, iv1 = sorted((round(v0 / c), round(v1 / c)))
        iu1, iv1 = max(iu1, iu0 + 1), max(iv1, iv0 + 1)  # at least one cell (thin walls)
        return slice(max(iv0, 0), min(iv1, self.nv)), slice(max(iu0, 0), min(iu1, self.nu))

    def ground(self, u0: float, u1: float, v0: float, v1: float, z: float, mat: int) -> None:
        s = self._sl(u0, u1, v0, v1)
        self.g[s] = z
        self.gm[s] = mat

    def rise(self, u0: float, u1: float, v0: float, v1: float, slope: float, start: float,
             top: float) -> None:
        """Ground rising from a block's edges inwards: flat for `start` metres, then up at `slope`
        to at most `top` above the sidewalk (embankments, raised gardens, low hills)."""
        s = self._sl(u0, u1, v0, v1)
        vv = (np.arange(s[0].start, s[0].stop) + 0.5) * self.c
        uu = (np.arange(s[1].start, s[1].stop) + 0.5) * self.c
        d = np.minimum(np.minimum(vv - v0, v1 - vv)[:, None], np.minimum(uu - u0, u1 - uu)[None, :])
        self.g[s] = (SIDEWALK_Z + np.clip(slope * (d - start), 0.0, top)).astype(np.float32)

    def solid(self, u0: float, u1: float, v0: float, v1: float, height: float, mat: int) -> None:
        """A solid box from the ground up to `height` above it."""
        s = self._sl(u0, u1, v0, v1)
        top = self.g[s] + np.float32(height)
        higher = top > self.top[s]
        self.top[s] = np.where(higher, top, self.top[s])
        self.tm[s] = np.where(higher, np.uint8(mat), self.tm[s])

    def floating(self, u0: float, u1: float, v0: float, v1: float, lo: float, hi: float,
                 mat: int) -> None:
        """A floating box between heights lo and hi above the ground (plates, lamp arms)."""
        s = self._sl(u0, u1, v0, v1)
        self._merge(s, self.g[s] + np.float32(lo), self.g[s] + np.float32(hi), mat, None)

    def crown(self, uc: float, vc: float, radius: float, zc: float, half_h: float) -> None:
        """An ellipsoidal tree crown centred at (uc, vc) and height zc above the ground."""
        s = self._sl(uc - radius, uc + radius, vc - radius, vc + radius)
        if s[0].stop <= s[0].start or s[1].stop <= s[1].start:
            return
        vv = (np.arange(s[0].start, s[0].stop) + 0.5) * self.c - vc
        uu = (np.arange(s[1].start, s[1].stop) + 0.5) * self.c - uc
        d2 = (vv[:, None] ** 2 + uu[None, :] ** 2) / radius**2
        inside = d2 < 1.0
        half = half_h * np.sqrt(np.clip(1.0 - d2, 0.0, 1.0))
        g = self.g[s]
        lo = (g + zc - half).astype(np.float32)
        hi = (g + zc + half).astype(np.float32)
        self._merge(s, lo, hi, M.FOLIAGE, inside)

    def _merge(self, s: tuple[slice, slice], lo: np.ndarray, hi: np.ndarray, mat: int,
               mask: np.ndarray | None) -> None:
        old_lo, old_hi = self.lo[s], self.hi[s]
        empty = old_hi <= old_lo
        new_lo = np.where(empty, lo, np.minimum(lo, old_lo))
        new_hi = np.where(empty, hi, np.maximum(hi, old_hi))
        if mask is None:
            mask = np.ones(lo.shape, dtype=bool)
        self.lo[s] = np.where(mask, new_lo, old_lo)
        self.hi[s] = np.where(mask, new_hi, old_hi)
        self.fm[s] = np.where(mask, np.uint8(mat), self.fm[s])

    def disc_solid(self, uc: float, vc: float, radius: float, height: float, mat: int) -> None:
        r = max(radius, self.c * 0.5)
        self.solid(uc - r, uc + r, vc - r, vc + r, height, mat)


class _Town:
    """Draws the town's content into a plan raster."""

    def __init__(self, grid: StreetGrid, plan: _Plan, rng: np.random.Generator) -> None:
        self.grid, self.p, self.rng = grid, plan, rng
        # front yards draw from their own stream (spawned: the main one does not advance)
        self.yard_rng = rng.spawn(1)[0]

    # --- helpers over an axis: `along` runs parallel to a street, `across` perpendicular ---
    @staticmethod
    def rect(vertical: bool, a0: float, a1: float, c0: float, c1: float
             ) -> tuple[float, float, float, float]:
        """(u0, u1, v0, v1) of the rectangle [a0, a1] along and [c0, c1] across a street;
        vertical=True means the street runs along v (a u-line street)."""
        return (c0, c1, a0, a1) if vertical else (a0, a1, c0, c1)

    def box(self, vertical: bool, a0: float, a1: float, c0: float, c1: float, height: float,
            mat: int) -> None:
        """A solid box over `rect(vertical, a0, a1, c0, c1)`."""
        self.p.solid(*self.rect(vertical, a0, a1, c0, c1), height, mat)

    def point(self, vertical: bool, a: float, c: float) -> tuple[float, float]:
        return (c, a) if vertical else (a, c)

    def tree(self, u: float, v: float, scale: float = 1.0,
             rng: np.random.Generator | None = None) -> None:
        rng = self.rng if rng is None else rng
        radius = rng.uniform(1.8, 3.4) * scale
        zc = rng.uniform(3.2, 5.5) * scale
        half_h = radius * rng.uniform(0.8, 1.2)
        self.p.disc_solid(u, v, rng.uniform(0.12, 0.25), zc, M.TRUNK)
        self.p.crown(u, v, radius, zc, half_h)

    def shrub(self, u: float, v: float, rng: np.random.Generator | None = None) -> None:
        """A porous bush standing on the ground."""
        rng = self.rng if rng is None else rng
        self.p.disc_solid(u, v, rng.uniform(0.5, 1.4), rng.uniform(0.5, 1.7), M.HEDGE)

    def verge(self, vertical: bool, a0: float, a1: float, c: float, side: float) -> None:
        """Vegetation along a street edge: bushes at irregular gaps, here and there a hedge."""
        rng = self.rng
        a = a0 + rng.uniform(0.5, 4.0)
        while a < a1 - 1.0:
            if rng.random() < 0.5:  # a stretch of hedge
                length = min(rng.uniform(6.0, 25.0), a1 - a)
                c0 = c + side * rng.uniform(0.0, 0.6)
                self.box(vertical, a, a + length, *_span((c0, c0 + side * rng.uniform(0.6, 1.2))),
                         rng.uniform(0.9, 1.9), M.HEDGE)
                a += length + rng.uniform(1.0, 5.0)
            else:
                u, v = self.point(vertical, a, c + side * rng.uniform(0.3, 1.8))
                self.shrub(u, v)
                a += rng.uniform(1.2, 4.5)

    def meadow(self, u0: float, u1: float, v0: float, v1: float, cover: float,
               rng: np.random.Generator | None = None) -> None:
        """Rough tall grass and weeds: patches of porous vegetation 0.3-1.1 m high over about
        `cover` of the area."""
        rng = self.rng if rng is None else rng
        area = max(u1 - u0, 0.0) * max(v1 - v0, 0.0)
        for _ in range(int(area * cover / 12.0)):
            w, d = rng.uniform(1.5, 5.0), rng.uniform(1.5, 5.0)
            u, v = rng.uniform(u0, max(u1 - w, u0)), rng.uniform(v0, max(v1 - d, v0))
            self.p.solid(u, u + w, v, v + d, rng.uniform(0.3, 1.1), M.TALL_GRASS)

    def front_yard(self, vertical: bool, a0: float, a1: float, edge: float, inward: float,
                   depth: float) -> None:
        """The strip between the sidewalk and a building set back `depth` metres: rough grass,
        bushes, now and then a small tree, and half the time a low boundary at the sidewalk."""
        rng = self.yard_rng
        y0, y1 = _span((edge + inward * 0.5, edge + inward * (depth - 0.5)))
        self.meadow(*self.rect(vertical, a0, a1, y0, y1), rng.uniform(0.2, 0.6), rng)
        a = a0 + rng.uniform(0.5, 3.0)
        while a < a1 - 0.5:
            u, v = self.point(vertical, a, edge + inward * rng.uniform(0.8, max(depth - 0.8, 0.9)))
            if rng.random() < 0.12:
                self.tree(u, v, rng.uniform(0.6, 0.85), rng)
            else:
                self.shrub(u, v, rng)
            a += rng.uniform(1.5, 5.0)
        if rng.random() < 0.5:
            mat = int(rng.choice([M.HEDGE, M.FENCE, M.WALL]))
            self.box(vertical, a0, a1, *_span((edge + inward * 0.3, edge + inward * 0.6)),
                     rng.uniform(0.8, 1.6), mat)

    def facade_details(self, vertical: bool, a0: float, a1: float, face: float, inward: float,
                       height: float, mat: int) -> None:
        """What stands out of a street facade: bay windows, pillars, porches and steps, bins."""
        rng = self.rng
        a = a0 + rng.uniform(0.3, 3.0)
        while a < a1 - 1.0:
            width = min(rng.uniform(0.6, 3.5), a1 - a)
            depth = rng.uniform(0.3, 1.2)
            tall = rng.uniform(0.8, height) if rng.random() < 0.6 else rng.uniform(0.6, 1.4)
            self.box(vertical, a, a + width, *_span((face, face - inward * depth)), tall,
                     mat if tall > 1.4 else M.WALL)
            a += width + rng.uniform(1.0, 6.0)

    def car(self, vertical: bool, a: float, c: float) -> None:
        """A parked car centred at (along a, across c), oriented along the street, either end
        first. Its cabin is porous glass (`materials.GLASS`): the beams pass the windows and
        return from inside and from the far side, so the car fills its footprint in the
        BEV-density images as parked cars do in BEVPlace's images of KITTI (a solid box
        returned from its outside only: about half of its footprint's pixels 6-10 m away, two
        thirds now). Its top is drawn in 0.2 m slices along its length (`CAR_PROFILE`: bonnet
        and boot below the roof), 0.15 m in from the shoulders, which lie lower."""
        rng = self.rng
        length = rng.uniform(3.8, 4.9)
        width = rng.uniform(1.7, 1.9)
        body = rng.uniform(0.8, 1.0)
        roof = float(rng.choice([1.42, 1.48, 1.55, 1.75]))
        cabin = rng.uniform(0.45, 0.6)  # share of the length under the roof and windows
        shift = rng.uniform(-0.2, 0.3)  # the cabin's centre from the car's, metres
        forward = -1.0 if shift > 0 else 1.0  # the cabin sits nearer the boot than the bumper
        n = max(round(length / 0.2), 1)
        for k in range(n):
            t = (k + 0.5) / n - 0.5 - shift / length  # from the cabin's centre, share of length
            height = _car_height(forward * t, cabin, body, roof)
            a0 = a - length / 2 + k * length / n
            a1 = a0 + length / n
            cabin_slice = height > body + 0.05
            self.box(vertical, a0, a1, c - width / 2, c + width / 2,
                     min(height, body) - 0.08, M.CAR)
            self.box(vertical, a0, a1, c - width / 2 + 0.15, c + width / 2 - 0.15, height,
                     M.GLASS if cabin_slice else M.CAR)

    # --- streets ---
    def streets(self) -> None:
        g = self.grid
        lines = [(True, float(x), float(h), float(w)) for x, h, w in
                 zip(g.u_lines, g.u_half_width, g.u_sidewalk, strict=True)]
        lines += [(False, float(x), float(h), float(w)) for x, h, w in
                  zip(g.v_lines, g.v_half_width, g.v_sidewalk, strict=True)]
        for vertical, x, half, walk in lines:  # sidewalks first, then carriageways over them
            length = g.size_v if vertical else g.size_u
            for side in (-1, 1):
                c0, c1 = sorted((x + side * half, x + side * (half + walk)))
                self.p.ground(*self.rect(vertical, 0, length, c0, c1), SIDEWALK_Z, M.SIDEWALK)
        for vertical, x, half, _ in lines:
            length = g.size_v if vertical else g.size_u
            self.p.ground(*self.rect(vertical, 0, length, x - half, x + half), 0.0, M.ASPHALT)
        for vertical, x, half, walk in lines:
            self.furnish_street(vertical, x, half, walk)

    def crossings(self, vertical: bool) -> list[tuple[float, float]]:
        """(start, end) along a street of the stretches between crossing streets."""
        g = self.grid
        if vertical:
            centres, halves, walks, length = g.v_lines, g.v_half_width, g.v_sidewalk, g.size_v
        else:
            centres, halves, walks, length = g.u_lines, g.u_half_width, g.u_sidewalk, g.size_u
        return self._block_edges(centres, halves, walks, float(length))

    def furnish_street(self, vertical: bool, x: float, half: float, walk: float) -> None:
        rng = self.rng
        centre_line = rng.random() < 0.75
        for a0, a1 in self.crossings(vertical):
            if centre_line:  # dashed centre marking
                for a in np.arange(a0 + 1.0, a1 - 3.0, 9.0).tolist():
                    self.p.ground(*self.rect(vertical, a, a + 3.0, x - 0.08, x + 0.08), 0.0, M.MARKING)
            for side in (-1, 1):
                kerb = x + side * half
                walk_mid = x + side * (half + walk / 2)
                # street lamps with an arm over the road
                for a in np.arange(a0 + rng.uniform(4, 15), a1 - 3, rng.uniform(26, 38)).tolist():
                    pole_c = x + side * (half + 0.5)
                    height = rng.uniform(7.0, 8.5)
                    u, v = self.point(vertical, a, pole_c)
                    self.p.disc_solid(u, v, 0.1, height, M.POLE)
                    arm0, arm1 = sorted((pole_c, pole_c - side * 1.6))
                    self.p.floating(*self.rect(vertical, a - 0.15, a + 0.15, arm0, arm1),
                                    height - 0.35, height, M.POLE)
                if a1 - a0 > 20 and rng.random() < 0.35:  # traffic sign near the crossing
                    a = a1 - 3.0 if side > 0 else a0 + 3.0
                    u, v = self.point(vertical, a, x + side * (half + 0.4))
                    self.p.disc_solid(u, v, 0.06, 2.6, M.POLE)
                    self.p.floating(u - 0.35, u + 0.35, v - 0.35, v + 0.35, 2.0, 2.7, M.SIGN)
                if walk >= 2.5 and rng.random() < 0.55:  # tree-lined street
                    step = rng.uniform(8.5, 13.0)
                    for a in np.arange(a0 + rng.uniform(3, 8), a1 - 3, step).tolist():
                        u, v = self.point(vertical, float(a + rng.normal(0, 0.4)), walk_mid)
                        self.tree(u, v, scale=0.85)
                if rng.random() < 0.85:  # bushes and hedges along the block's edge
                    self.verge(vertical, a0, a1, x + side * (half + walk), side)
                if a1 - a0 > 25 and rng.random() < PARKING_P:  # parked cars along the kerb
                    a = a0 + rng.uniform(6, 10)
                    while a < a1 - 10:
                        if rng.random() < 0.85:
                            self.car(vertical, a + 2.4, kerb - side * 1.1)
                            a += rng.uniform(5.4, 7.5)
                        else:
                            a += rng.uniform(5, 14)

    # --- blocks ---
    def blocks(self) -> None:
        g = self.grid
        us = self._block_edges(g.u_lines, g.u_half_width, g.u_sidewalk, g.size_u)
        vs = self._block_edges(g.v_lines, g.v_half_width, g.v_sidewalk, g.size_v)
        kinds = ("urban", "residential", "park", "open", "parking")
        weights = np.array([0.38, 0.30, 0.12, 0.08, 0.12])
        for u0, u1 in us:
            for v0, v1 in vs:
                kind = kinds[int(self.rng.choice(len(kinds), p=weights))]
                if kind in TERRAIN and self.rng.random() < TERRAIN_P:
                    slope, start, top = TERRAIN[kind]
                    self.p.rise(u0, u1, v0, v1, self.rng.uniform(*slope), self.rng.uniform(*start),
                                self.rng.uniform(*top))
                getattr(self, f"block_{kind}")(u0, u1, v0, v1)

    @staticmethod
    def _block_edges(lines: np.ndarray, half: np.ndarray, walk: np.ndarray,
                     size: float) -> list[tuple[float, float]]:
        edges = [0.0]
        for c, h, w in zip(lines, half, walk, strict=True):
            edges += [float(c - h - w), float(c + h + w)]
        edges.append(size)
        return [(edges[k], edges[k + 1]) for k in range(0, len(edges), 2)]

    def _sides(self, u0: float, u1: float, v0: float, v1: float) -> list[tuple[bool, float, float, float, float]]:
        """The four sides of a block: (vertical, along0, along1, edge, inward sign)."""
        return [(True, v0, v1, u0, 1.0), (True, v0, v1, u1, -1.0),
                (False, u0, u1, v0, 1.0), (False, u0, u1, v1, -1.0)]

    def block_urban(self, u0: float, u1: float, v0: float, v1: float) -> None:
        rng = self.rng
        setback = float(rng.choice(URBAN_SETBACKS_M))
        heights = (7.0, 9.5, 12.0, 15.0, 18.0, 22.0)
        depth_max = max(min(u1 - u0, v1 - v0) / 2 - 1.0, 4.0)
        for vertical, a0, a1, edge, inward in self._sides(u0, u1, v0, v1):
            a = a0 + rng.uniform(0, 4)
            while a < a1 - 6:
                width = min(rng.uniform(10, 26), a1 - a)
                depth = min(rng.uniform(9, 16), depth_max)
                height = float(rng.choice(heights)) + rng.uniform(-0.4, 0.4)
                c0 = edge + inward * setback
                facade = int(rng.choice(M.FACADES))
                self.box(vertical, a, a + width, *_span((c0, c0 + inward * depth)), height, facade)
                self.facade_details(vertical, a, a + width, c0, inward, height, facade)
                if setback >= 2.0:
                    self.front_yard(vertical, a, a + width, edge, inward, setback)
                if rng.random() < 0.25:  # an L-shaped wing to the back
                    wing = width * rng.uniform(0.25, 0.45)
                    w0 = a if rng.random() < 0.5 else a + width - wing
                    deeper = min(depth + rng.uniform(4, 10), depth_max)
                    self.box(vertical, w0, w0 + wing, *_span((c0, c0 + inward * deeper)), height, int(rng.choice(M.FACADES)))
                a += width + float(rng.choice([0.0, 0.0, 0.0, 1.5, 3.0, 6.0]))
        for _ in range(int(rng.integers(0, 4))):  # courtyard trees
            self.tree(rng.uniform(u0 + 20, max(u1 - 20, u0 + 21)), rng.uniform(v0 + 20, max(v1 - 20, v0 + 21)))

    def block_residential(self, u0: float, u1: float, v0: float, v1: float) -> None:
        rng = self.rng
        setback = rng.uniform(3.0, 6.0)
        boundary = int(rng.choice(4, p=[0.1, 0.45, 0.25, 0.2]))  # 0 none, 1 hedge, 2 fence, 3 wall
        house_w, house_d = rng.uniform(8, 12), rng.uniform(8, 11)  # one house type per block
        heights = (5.5, 6.5, 7.5, 9.0)
        for vertical, a0, a1, edge, inward in self._sides(u0, u1, v0, v1):
            a = a0 + setback + 2
            while a < a1 - setback - house_w:
                c0 = edge + inward * setback
                self.box(vertical, a, a + house_w, *_span((c0, c0 + inward * house_d)),
                         float(rng.choice(heights)), int(rng.choice(M.FACADES)))
                lot = house_w + rng.uniform(4, 9)
                if setback > 4.5 and rng.random() < 0.5:  # a car in the driveway (the boundary's gap)
                    self.car(not vertical, edge + inward * setback / 2, a + lot - 2.0)
                if boundary:  # front boundary with a driveway gap
                    b = edge + inward * 0.4
                    thick = {1: 0.8, 2: 0.2, 3: 0.3}[boundary]
                    height = {1: rng.uniform(1.1, 1.8), 2: rng.uniform(1.1, 1.6), 3: rng.uniform(0.8, 1.5)}[boundary]
                    mat = {1: M.HEDGE, 2: M.FENCE, 3: M.WALL}[boundary]
                    self.box(vertical, a - 1.0, a + lot - 4.0, *_span((b, b + inward * thick)), height, mat)
                if rng.random() < 0.5:  # an unkempt front garden
                    g0, g1 = _span((edge + inward * 0.8, edge + inward * max(setback - 0.5, 1.0)))
                    self.meadow(*self.rect(vertical, a, a + house_w, g0, g1), rng.uniform(0.3, 0.8))
                for _ in range(int(rng.integers(1, 5))):  # bushes in the front garden
                    u, v = self.point(vertical, a + rng.uniform(0, house_w), edge + inward * rng.uniform(1.2, max(setback - 1.0, 1.3)))
                    self.shrub(u, v)
                if rng.random() < 0.6:  # garden tree between houses
                    u, v = self.point(vertical, a + house_w + rng.uniform(1.5, 3.5), edge + inward * rng.uniform(setback, setback + house_d + 4))
                    self.tree(u, v, scale=rng.uniform(0.7, 1.0))
                a += lot

    def block_park(self, u0: float, u1: float, v0: float, v1: float) -> None:
        rng = self.rng
        step = rng.uniform(8, 12)
        for u in np.arange(u0 + 4, u1 - 3, step).tolist():
            for v in np.arange(v0 + 4, v1 - 3, step).tolist():
                if rng.random() < 0.62:
                    self.tree(u + rng.uniform(-2.5, 2.5), v + rng.uniform(-2.5, 2.5))
                if rng.random() < 0.5:
                    self.shrub(u + step / 2 + rng.uniform(-2, 2), v + step / 2 + rng.uniform(-2, 2))
        self.meadow(u0, u1, v0, v1, rng.uniform(0.1, 0.35))
        if rng.random() < 0.5:
            self._perimeter(u0, u1, v0, v1, M.FENCE, 0.2, rng.uniform(1.0, 1.5))

    def block_open(self, u0: float, u1: float, v0: float, v1: float) -> None:
        rng = self.rng
        if rng.random() < 0.7:
            self._perimeter(u0, u1, v0, v1, M.FENCE, 0.2, rng.uniform(1.0, 1.6))
        for _ in range(int(rng.integers(0, 5))):
            self.tree(rng.uniform(u0 + 3, u1 - 3), rng.uniform(v0 + 3, v1 - 3))
        for _ in range(int(rng.integers(3, 15))):
            self.shrub(rng.uniform(u0 + 2, u1 - 2), rng.uniform(v0 + 2, v1 - 2))
        self.meadow(u0, u1, v0, v1, rng.uniform(0.3, 0.7))

    def block_parking(self, u0: float, u1: float, v0: float, v1: float) -> None:
        rng = self.rng
        self.p.ground(u0, u1, v0, v1, SIDEWALK_Z, M.ASPHALT)
        for v in np.arange(v0 + 5, v1 - 5, 7.5):
            for u in np.arange(u0 + 3, u1 - 3, 2.6):
                if rng.random() < 0.65:
                    self.car(True, float(v), float(u))
        if rng.random() < 0.6:
            self._perimeter(u0, u1, v0, v1, M.HEDGE, 0.8, rng.uniform(1.0, 1.6))

    def _perimeter(self, u0: float, u1: float, v0: float, v1: float, mat: int, thick: float,
                   height: float) -> None:
        for vertical, a0, a1, edge, inward in self._sides(u0, u1, v0, v1):
            c0 = edge + inward * 0.5
            self.box(vertical, a0 + 0.5, a1 - 0.5, *_span((c0, c0 + inward * thick)), height, mat)


def make_world(grid: StreetGrid, rng: np.random.Generator, cell: float = 0.2) -> World:
    """Draw a town on `grid` and resample it into the (warped) world frame."""
    plan = _Plan(grid.size_u, grid.size_v, cell)
    town = _Town(grid, plan, rng)
    town.blocks()
    town.streets()
    nx, ny = plan.nu, plan.nv
    out = {name: np.empty((ny, nx), dtype=getattr(plan, name).dtype)
           for name in ("g", "gm", "top", "tm", "lo", "hi", "fm")}
    xs = (np.arange(nx) + 0.5) * cell
    chunk = max(1, 2_000_000 // nx)
    for r0 in range(0, ny, chunk):
        ys = (np.arange(r0, min(r0 + chunk, ny)) + 0.5) * cell
        x, y = np.meshgrid(xs, ys)
        u, v = grid.warp.to_plan(x, y)
        iu = np.floor(u / cell).astype(np.int64)
        iv = np.floor(v / cell).astype(np.int64)
        ok = (iu >= 0) & (iu < nx) & (iv >= 0) & (iv < ny)
        iu, iv = np.clip(iu, 0, nx - 1), np.clip(iv, 0, ny - 1)
        for name, arr in out.items():
            src = getattr(plan, name)[iv, iu]
            default = {"g": SIDEWALK_Z, "gm": M.GRASS}.get(name, 0)
            arr[r0:r0 + len(ys)] = np.where(ok, src, np.asarray(default, dtype=src.dtype))
        lift = grid.terrain.height(x, y).astype(np.float32)  # every height rides on the land
        for name in ("g", "top", "lo", "hi"):
            out[name][r0:r0 + len(ys)] += lift
    return World(cell, out["g"], out["gm"], out["top"], out["tm"], out["lo"], out["hi"], out["fm"], grid)
