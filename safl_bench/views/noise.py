"""Viewpoint-noise conditions T{a}R{b} of the paper's protocol and their seeded sampling.

A condition moves the viewpoint of each query frame: a translation drawn uniformly over the disc
of radius `a` metres in the ground plane and a heading change drawn uniformly from (-b/2, b/2)
radians. The offsets are expressed in the robot's own frame (x forward, y left) and are applied
where the top-view map is rendered (see `safl_bench.views.topview`), never by warping a finished image.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from safl_bench.errors import ConfigError

_NAME = re.compile(r"^T(\d+(?:\.\d+)?)R(\d+(?:\.\d+)?)$")


def _fmt(value: float) -> str:
    return f"{value:g}"


@dataclass(frozen=True, order=True)
class Condition:
    """A viewpoint-noise condition: translation radius `a` (m) and heading range `b` (rad)."""

    translation_m: float = 0.0
    heading_rad: float = 0.0

    def __post_init__(self) -> None:
        for label, value in (("translation", self.translation_m), ("heading", self.heading_rad)):
            if not np.isfinite(value) or value < 0:
                raise ConfigError(f"{label} noise must be a finite value >= 0, got {value!r}")

    @property
    def name(self) -> str:
        """The paper's name of the condition, e.g. 'T5R1.5'."""
        return f"T{_fmt(self.translation_m)}R{_fmt(self.heading_rad)}"

    @property
    def is_clean(self) -> bool:
        """True for T0R0 (no noise)."""
        return self.translation_m == 0 and self.heading_rad == 0

    @classmethod
    def parse(cls, name: str) -> Condition:
        """Parse 'T{a}R{b}' (e.g. 'T10R1.5')."""
        match = _NAME.match(name.strip())
        if not match:
            raise ConfigError(f"not a noise condition: {name!r} (expected e.g. 'T5R1.5')")
        return cls(float(match.group(1)), float(match.group(2)))

    def __str__(self) -> str:
        return self.name


CLEAN = Condition(0.0, 0.0)

#: The twelve conditions of the paper's Table II, in its column order.
PAPER_CONDITIONS: tuple[Condition, ...] = tuple(
    Condition(a, b) for b in (1.0, 1.5, 2.0) for a in (1.0, 5.0, 10.0, 20.0)
)


def sample_offsets(n: int, condition: Condition, seed: int) -> np.ndarray:
    """Per-frame viewpoint offsets (n, 3): dx, dy (m, robot frame) and dtheta (rad).

    Translation is uniform over the disc of radius a (area-uniform: r = a*sqrt(u)); heading is
    uniform in (-b/2, b/2). The stream depends only on (seed, condition), so one condition's
    offsets do not change when another condition is added or removed.
    """
    if n < 0:
        raise ConfigError(f"number of frames must be >= 0, got {n}")
    if int(seed) < 0:
        raise ConfigError(f"noise seed must be an integer >= 0, got {seed}")
    key = [int(seed), round(condition.translation_m * 1000), round(condition.heading_rad * 1000)]
    rng = np.random.default_rng(np.random.SeedSequence(key))
    u, phi, h = rng.random((3, n))
    radius = condition.translation_m * np.sqrt(u)
    angle = 2.0 * np.pi * phi
    dtheta = (h - 0.5) * condition.heading_rad
    return np.stack([radius * np.cos(angle), radius * np.sin(angle), dtheta], axis=1)
