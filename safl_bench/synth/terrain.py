"""The lie of the land: a smooth height field under the whole synthetic town.

KITTI is not flat: the ground under sequence 00 spans 20 m of height, under 02 49 m, and the
sensor's roll and pitch vary by about 1 degree within a hundred frames (BEVPlace's poses of 00
and 02, high-passed). What a top view keeps of that is the ground a few tens of metres away
rising above the ground cut of the BEV-density encoding (arcs of scan rings in real images).
Version 1 of the synthetic data had a flat town; here the town lies on a sum of plane waves,
long gentle hills plus shorter undulations, and the vehicle follows it (height, pitch and roll
from the field's gradient).

Choices the data leaves open: hills of 300-900 m wavelength and 2-7 m amplitude (slopes of a
few per cent, as KITTI's height ranges imply over its few-kilometre routes); undulations of
60-160 m and 0.15-0.5 m (dips and crests that bring the ground at 20-25 m up to the cut);
the field is the same in the world frame for streets, blocks and everything on them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Terrain:
    """h(x, y) = sum_k a_k sin(kx_k x + ky_k y + phase_k), world metres."""

    amplitude: tuple[float, ...]
    kx: tuple[float, ...]
    ky: tuple[float, ...]
    phase: tuple[float, ...]

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Ground height offset at world points."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        out = np.zeros(np.broadcast(x, y).shape)
        for a, kx, ky, ph in zip(self.amplitude, self.kx, self.ky, self.phase, strict=True):
            out += a * np.sin(kx * x + ky * y + ph)
        return out

    def gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dh/dx, dh/dy) at world points."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        gx = np.zeros(np.broadcast(x, y).shape)
        gy = np.zeros_like(gx)
        for a, kx, ky, ph in zip(self.amplitude, self.kx, self.ky, self.phase, strict=True):
            c = a * np.cos(kx * x + ky * y + ph)
            gx += kx * c
            gy += ky * c
        return gx, gy


FLAT = Terrain((), (), (), ())

#: (wavelength m, amplitude m) ranges and how many waves of each kind
HILLS = ((300.0, 900.0), (2.0, 7.0), 2)
UNDULATIONS = ((60.0, 160.0), (0.15, 0.5), 3)


def make_terrain(rng: np.random.Generator) -> Terrain:
    """A random height field: `HILLS` and `UNDULATIONS` in random directions and phases."""
    amp: list[float] = []
    kx: list[float] = []
    ky: list[float] = []
    phase: list[float] = []
    for (l0, l1), (a0, a1), n in (HILLS, UNDULATIONS):
        for _ in range(n):
            k = 2 * np.pi / rng.uniform(l0, l1)
            direction = rng.uniform(0, 2 * np.pi)
            amp.append(float(rng.uniform(a0, a1)))
            kx.append(float(k * np.cos(direction)))
            ky.append(float(k * np.sin(direction)))
            phase.append(float(rng.uniform(0, 2 * np.pi)))
    return Terrain(tuple(amp), tuple(kx), tuple(ky), tuple(phase))
