"""The street layout of a synthetic town: a grid of streets, bent into curves by a smooth warp.

Streets are straight lines u = U_i and v = V_j in a flat "plan" frame (u, v); the world frame
(x, y) is a smooth, invertible warp of it, so grid streets become gently curving ones while
blocks, lots and parking rows stay simple rectangles in the plan frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from safl_bench.synth.terrain import FLAT, Terrain, make_terrain

#: margin of blocks beyond the outermost streets, metres
MARGIN_M = 55.0


@dataclass(frozen=True)
class Warp:
    """x = u + sum A sin(2 pi y / L + phi), y = v + sum B sin(2 pi x / M + psi).

    Written as plan = world - offset(world), so plan coordinates of a world point are explicit
    (used to rasterise) and world coordinates of a plan point come from a fixed-point iteration
    (used for routes); the slope of the offsets stays below 0.35, so both are well defined.
    """

    ax: tuple[float, ...]
    lx: tuple[float, ...]
    px: tuple[float, ...]
    ay: tuple[float, ...]
    ly: tuple[float, ...]
    py: tuple[float, ...]

    def offset_x(self, y: np.ndarray) -> np.ndarray:
        out = np.zeros_like(y)
        for a, length, phase in zip(self.ax, self.lx, self.px, strict=True):
            out += a * np.sin(2 * np.pi * y / length + phase)
        return out

    def offset_y(self, x: np.ndarray) -> np.ndarray:
        out = np.zeros_like(x)
        for a, length, phase in zip(self.ay, self.ly, self.py, strict=True):
            out += a * np.sin(2 * np.pi * x / length + phase)
        return out

    def to_plan(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Plan coordinates (u, v) of world points."""
        return x - self.offset_x(y), y - self.offset_y(x)

    def to_world(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World coordinates (x, y) of plan points (fixed-point iteration, contraction < 0.35)."""
        x, y = np.array(u, dtype=np.float64), np.array(v, dtype=np.float64)
        for _ in range(40):
            x_new = u + self.offset_x(y)
            y_new = v + self.offset_y(x)
            if max(np.max(np.abs(x_new - x), initial=0), np.max(np.abs(y_new - y), initial=0)) < 1e-9:
                return x_new, y_new
            x, y = x_new, y_new
        return x, y


@dataclass(frozen=True)
class StreetGrid:
    """Street lines of a town in the plan frame, with their widths."""

    u_lines: np.ndarray  # (nu,) plan u of the north-south streets
    v_lines: np.ndarray  # (nv,) plan v of the east-west streets
    u_half_width: np.ndarray  # (nu,) half width of the carriageway, metres
    v_half_width: np.ndarray
    u_sidewalk: np.ndarray  # (nu,) sidewalk width, metres
    v_sidewalk: np.ndarray
    size_u: float  # plan extent [0, size_u] x [0, size_v]
    size_v: float
    warp: Warp
    #: the ground's height field (world frame) under streets and blocks alike
    terrain: Terrain = FLAT

    def node(self, i: int, j: int) -> tuple[float, float]:
        """Plan position of the crossing of street line u_i and v_j."""
        return float(self.u_lines[i]), float(self.v_lines[j])


def make_street_grid(lines: int, rng: np.random.Generator) -> StreetGrid:
    """A random street grid with `lines` streets each way (irregular block sizes, curved)."""

    def axis() -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        spacing = rng.uniform(70.0, 115.0, size=max(lines - 1, 0))
        pos = MARGIN_M + np.concatenate([[0.0], np.cumsum(spacing)])
        half = rng.choice([4.5, 5.0, 6.0], size=lines)
        walk = rng.choice([1.5, 2.5, 3.5], size=lines)
        return pos, half, walk, float(pos[-1] + MARGIN_M)

    u, uh, uw, size_u = axis()
    v, vh, vw, size_v = axis()
    # Two sinusoids per axis: a long bend and a shorter wiggle; amplitudes vary per town so
    # some towns are almost a grid and others have clearly curved streets.
    bend = rng.uniform(0.3, 1.0)
    warp = Warp(
        ax=(bend * rng.uniform(8, 18), rng.uniform(1.5, 4)),
        lx=(rng.uniform(500, 850), rng.uniform(200, 320)),
        px=(rng.uniform(0, 2 * np.pi), rng.uniform(0, 2 * np.pi)),
        ay=(bend * rng.uniform(8, 18), rng.uniform(1.5, 4)),
        ly=(rng.uniform(500, 850), rng.uniform(200, 320)),
        py=(rng.uniform(0, 2 * np.pi), rng.uniform(0, 2 * np.pi)),
    )
    return StreetGrid(u, v, uh, vh, uw, vw, size_u, size_v, warp, make_terrain(rng))
