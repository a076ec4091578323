"""Settings of the synthetic dataset: which sequences exist, how long they are, the sensor.

Everything that changes the generated files lives in `SynthConfig` (recorded in each
sequence's manifest), so a changed setting makes `ensure` regenerate the sequence.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from safl_bench.errors import ConfigError

#: Bumped whenever the generator's output changes for the same seed and config. Version "1" was
#: the data of the synthetic tasks' task version v0 (e.g. SAFL/Synth00-T1R1-v0), version "2" that
#: of v1, version "3" that of v2, version "4" that of v3; version "5" is that of v4 and v5 (paper)
#: and v4 (revisit); version "6" (routes that obey a loop rule, `synth.routes.ROUTE_RULES`) that of
#: v6. A bump needs new synthetic task versions in `safl_bench.tasks.builtin`.
GENERATOR_VERSION = "6"
#: The data versions this generator can make, oldest first: "5" stays so that its tasks keep
#: running (its sequences live in their own folder, `synth.default_root`); it differs from "6"
#: only in the route rule.
GENERATOR_VERSIONS: tuple[str, ...] = ("5", "6")

DEFAULT_SEED = 0
#: Test sequences: 00 in the role of KITTI 00 (revisits driving the same way), 09 in that of
#: KITTI 08 (revisits driving the opposite way; `synth.routes` says why).
TEST_SEQUENCES: tuple[str, ...] = ("00", "09")
#: Training sequences, in the roles of KITTI 01-08.
TRAIN_SEQUENCES: tuple[str, ...] = ("01", "02", "03", "04")
ALL_SEQUENCES: tuple[str, ...] = TEST_SEQUENCES + TRAIN_SEQUENCES
#: Sequences whose scans are cast when a view needs them, never written (`synth.generate`): the
#: long drive L0, 20 000 frames (about 16 km) over a 14 x 14 town of about 1.3 x 1.2 km, which
#: would take 32 GB as KITTI scans (1.6 MB each). About 15 % of its frames revisit a place (8 %
#: the same way, 7 % the opposite way; data seed 0, `routes.revisit_kinds`), so most of the drive
#: is new ground, as on a city-scale run. Not in `ALL_SEQUENCES` (`safl-bench data synth` without
#: names): it is generated when its task (`SAFL/SynthL0-Revisit-v6`) runs, or by name.
STREAMED_SEQUENCES: tuple[str, ...] = ("L0",)
KNOWN_SEQUENCES: tuple[str, ...] = ALL_SEQUENCES + STREAMED_SEQUENCES


@dataclass(frozen=True)
class SequenceSpec:
    """The shape of one sequence: its length and the size of its town."""

    frames: int
    #: number of street lines in each direction of the (warped) street grid
    grid_lines: int
    #: revisits the route must have (`synth.routes.REVISITS`): "same" (some street driven again
    #: the same way, none the opposite way), "opposite" (some street driven again the opposite
    #: way), "both", "any", "none"
    revisits: str


#: Default lengths: ~1400 frames (140 s) for the main test sequence, like a short KITTI 00.
SEQUENCE_SPECS: dict[str, SequenceSpec] = {
    "00": SequenceSpec(frames=1400, grid_lines=5, revisits="same"),
    "09": SequenceSpec(frames=800, grid_lines=4, revisits="opposite"),
    "01": SequenceSpec(frames=350, grid_lines=4, revisits="none"),
    "02": SequenceSpec(frames=350, grid_lines=4, revisits="none"),
    "03": SequenceSpec(frames=350, grid_lines=4, revisits="none"),
    "04": SequenceSpec(frames=350, grid_lines=4, revisits="none"),
    # the long drive (`STREAMED_SEQUENCES`): it comes back either way, as a long real drive does
    # (the "same" rule, no opposite pass at all, is not met by a 16 km walk)
    "L0": SequenceSpec(frames=20000, grid_lines=14, revisits="any"),
}
#: Changes to `SEQUENCE_SPECS` per data version. From version 6 sequence 09 has 1000 frames: at
#: 800 (about 700 m) a walk under the loop rule (`synth.routes.LoopRule`: no loop shorter than
#: 550 m) rarely fits an opposite-direction revisit on its 4 x 4 grid (1 of data seeds 0-7 found
#: one in 2000 walks); at 1000 frames all 8 do.
SEQUENCE_SPEC_CHANGES: dict[str, dict[str, SequenceSpec]] = {
    "6": {"09": SequenceSpec(frames=1000, grid_lines=4, revisits="opposite")},
}


@dataclass(frozen=True)
class SynthConfig:
    """Every setting that changes the generated files (defaults: the benchmark's data set).

    `frames` overrides the per-sequence length (tests use a handful of frames) and then drops
    the revisit requirement (a short route cannot come back); `grid_lines` overrides the town
    size.
    """

    frames: int | None = None
    grid_lines: int | None = None
    #: raster cell of the 2.5D world, metres
    cell_m: float = 0.2
    #: horizontal angular step of the spinning sensor (HDL-64E: 0.09-0.35 deg; 0.18 at KITTI's
    #: 10 Hz, about 100k points a scan here against KITTI's 120k). Data version 2 used 0.35
    #: (about 51k points), half the generation time; at 0.18 the BEV-density non-zero share of
    #: two towns rose from 6.3 / 5.4 % to 6.7 / 5.8 % (seeds 0 / 1; KITTI 00 / 02: 6.3 / 7.4 %)
    #: and the mean non-zero value from 0.27 / 0.28 to 0.29 / 0.30 (KITTI: 0.35 / 0.30).
    azimuth_res_deg: float = 0.18
    #: number of laser beams (HDL-64E: 64)
    beams: int = 64
    elevation_top_deg: float = 2.0
    elevation_bottom_deg: float = -24.8
    max_range_m: float = 100.0
    sensor_height_m: float = 1.73
    range_noise_m: float = 0.02
    dropout: float = 0.03
    rate_hz: float = 10.0

    def __post_init__(self) -> None:
        if self.frames is not None and self.frames < 2:
            raise ConfigError(f"frames must be at least 2, got {self.frames}")
        if self.grid_lines is not None and self.grid_lines < 2:
            raise ConfigError(f"grid_lines must be at least 2, got {self.grid_lines}")
        if not 0.01 <= self.azimuth_res_deg <= 10:
            raise ConfigError(f"azimuth_res_deg must be in [0.01, 10], got {self.azimuth_res_deg}")
        if self.beams < 1 or self.max_range_m <= 5 or self.cell_m <= 0:
            raise ConfigError("beams must be >= 1, max_range_m > 5 and cell_m > 0")

    def spec(self, name: str, version: str = GENERATOR_VERSION) -> SequenceSpec:
        """The spec of sequence `name` in data `version` with this config's overrides applied."""
        base = SEQUENCE_SPEC_CHANGES.get(str(version), {}).get(name, SEQUENCE_SPECS.get(name))
        if base is None:
            raise ConfigError(
                f"unknown synthetic sequence {name!r}; known: {', '.join(KNOWN_SEQUENCES)}"
            )
        return dataclasses.replace(
            base,
            frames=self.frames if self.frames is not None else base.frames,
            revisits=base.revisits if self.frames is None else "none",
            grid_lines=self.grid_lines if self.grid_lines is not None else base.grid_lines,
        )

    def elevations_deg(self) -> np.ndarray:
        """Beam elevations, top to bottom, HDL-64E-like: a denser upper block, a sparser lower one."""
        if self.beams == 1:
            return np.array([self.elevation_bottom_deg])
        half = self.beams // 2
        split_hi = self.elevation_top_deg + 0.39 * (self.elevation_bottom_deg - self.elevation_top_deg)
        split_lo = split_hi - 0.5
        upper = np.linspace(self.elevation_top_deg, split_hi, half)
        lower = np.linspace(split_lo, self.elevation_bottom_deg, self.beams - half)
        return np.concatenate([upper, lower])


def sequence_seed(seed: int, name: str) -> np.random.SeedSequence:
    """The seed sequence of one synthetic sequence: depends on the seed and the name only."""
    return np.random.SeedSequence([int(seed) & 0xFFFFFFFF, *name.encode("utf-8")])
