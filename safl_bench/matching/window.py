"""Eq. 5's contrast-enhancement window chosen from the data: the ``dip`` rule.

The paper gives no window for its local contrast enhancement (Eq. 5). The ``paper-r10`` preset
takes OpenSeqSLAM's 10 frames, a value made for image sequences whose true match is a narrow
dip a few frames wide. On these tasks it is not: they take every 4th frame (about 3.5 m apart)
and a top view is 60-80 m wide, so two views keep much of their content for tens of frames. A
10-frame window (+-5 frames, +-17 m) then lies inside the true match's own dip, the z-score of
the true frame is taken against its own valley, and the enhancement erases the match it should
sharpen (issue 45: the true frame's median rank in its row went from 4 to 46 on synthetic 00,
from 1 to 47 on real KITTI 00).

The rule measures the dip where no ground truth and no score is involved: on the DATABASE
alone, by the method's own difference, so it is the dip of the descriptor the cell scores.

1. Sample `DIP_ROWS` database frames, evenly spaced (`sample_rows`; all of them when the
   database is smaller), and compute their differences to every database frame (the cell's
   distance: `Method.distance` or plain L2, whatever the difference matrix uses).
2. Divide each sampled row by its median over the other frames: 1 is "a typical other place".
   Rows whose median is not positive (a constant row) carry no dip and are left out.
3. The self-difference profile p(k) is the median over the sampled rows of the normalised
   difference at lags -k and +k (both sides pooled): p(0) = 0, and p rises to about 1 as the
   frames stop sharing what they see.
4. The dip's half-width h is the first lag at which p(k) >= `DIP_LEVEL` (0.9: nine tenths of
   the way back to a typical other place).
5. The window is R = 2 * `DIP_FACTOR` * h frames, centred (h * `DIP_FACTOR` on each side), at
   most the whole database: with `DIP_FACTOR` = 4 the dip (2h + 1 frames) fills at most about a
   quarter of the window, so the window's mean and spread are those of the places around the
   dip, not of the dip itself, and the window still follows how distinctive the database is
   from one stretch to the next (the point of Eq. 5).

Both constants (`DIP_LEVEL`, `DIP_FACTOR`) were fixed by this argument before any score under
the rule was seen; `DIP_ROWS` bounds the cost (64 rows of the database, against the Nq rows of
the difference matrix). On the training sequences they give, with the shipped weights
(BEVPlace's top views of KITTI 02, every 4th frame; the method's own difference): Stable-AFL
h = 16 (R = 128), BiGAN h = 10 (R = 80), SAD h = 5 (R = 40). Changing a constant changes
matches: it is a new rule name, not a new value under this one.

Where the window would be longer than the database, it is the whole database (each row's
z-score against all of its frames; `WindowChoice.capped`). On a database shorter than its own
dip that is what happens: the row median then lies inside the dip, so the profile reaches the
level early, at a lag of about a quarter of the database or more, and 8h covers all of it.

Fallback (stated in the record, never a NaN): when no sampled row has a positive median, or the
profile never reaches `DIP_LEVEL`, the dip cannot be measured and the window is the whole
database too; `WindowChoice.fallback` says why.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from safl_bench.errors import DataError

#: The level (of the row median) at which the self-difference profile has left the dip.
DIP_LEVEL = 0.9
#: Window half-width in dip half-widths: the dip fills about 1 / DIP_FACTOR of the window.
DIP_FACTOR = 4
#: Database frames whose self-difference rows the profile is measured on.
DIP_ROWS = 64
#: The rule's name, as `MatcherConfig.enhance_rule` holds it.
RULE = "dip"
#: Where a record's ``matcher`` field keeps the rule's choice for the cell (`WindowChoice.to_dict`).
RECORD_KEY = "enhancement"


@dataclass(frozen=True)
class WindowChoice:
    """What the ``dip`` rule chose for one database: the window R (frames, centred; what
    ``enhance_window`` would hold), the dip's half-width h (None on the fallback), how many
    database frames the profile was measured on, the fallback's reason (None when the dip was
    measured) and the profile p(0..h) (empty on the fallback)."""

    window: int
    half_width: int | None
    rows: int
    fallback: str | None = None
    profile: list[float] = field(default_factory=list)
    #: 2 * DIP_FACTOR * h exceeded the database, so the window is all of it
    capped: bool = False

    def to_dict(self) -> dict[str, Any]:
        """What records keep (the ``enhancement`` entry of their ``matcher`` field)."""
        return {"rule": RULE, "window": self.window, "half_width": self.half_width,
                "rows": self.rows, "level": DIP_LEVEL, "factor": DIP_FACTOR,
                "fallback": self.fallback, "capped": self.capped,
                "profile": [round(p, 4) for p in self.profile]}

    def describe(self) -> str:
        """One line for logs: the window and where it came from."""
        if self.fallback is not None:
            return f"enhancement window {self.window} frames (whole database: {self.fallback})"
        cap = ", capped at the whole database" if self.capped else ""
        return (f"enhancement window {self.window} frames (dip half-width {self.half_width} "
                f"frames x 2 x {DIP_FACTOR}{cap}, measured on {self.rows} database frames)")


def sample_rows(n_database: int, rows: int = DIP_ROWS) -> np.ndarray:
    """The database frames the profile is measured on: `rows` evenly spaced, or all."""
    if n_database < 1:
        raise DataError("the enhancement-window rule needs a database of at least one frame")
    return np.unique(np.linspace(0, n_database - 1, min(n_database, rows)).round().astype(np.int64))


def self_difference_profile(rows: np.ndarray, at: np.ndarray, *,
                            until: float | None = None) -> np.ndarray:
    """p(k) (module doc, 2-3): `rows` (len(at), Ndb) are the differences of database frames
    `at` to every database frame. With `until`, p is computed over growing lag ranges and
    returned as far as the first range in which it reaches `until` (the rule needs no more);
    else for k = 0 .. Ndb - 1. NaN where every sampled row is constant."""
    d = np.asarray(rows, dtype=np.float64)
    at = np.asarray(at, dtype=np.int64)
    if d.ndim != 2 or d.shape[0] != len(at):
        raise DataError(f"self-difference rows must be ({len(at)}, Ndb), got shape {d.shape}")
    if not np.isfinite(d).all():
        raise DataError(f"the database's self-difference has "
                        f"{int(np.count_nonzero(~np.isfinite(d)))} NaN or infinite entries")
    n = d.shape[1]
    if n < 2:
        return np.full(n, np.nan)
    self_cell = np.zeros(d.shape, dtype=bool)
    self_cell[np.arange(len(at)), at] = True
    median = np.median(d[~self_cell].reshape(len(at), n - 1), axis=1)
    keep = median > 0
    if not keep.any():
        return np.full(n, np.nan)
    norm = d[keep] / median[keep, None]
    at = at[keep]
    rows_idx = np.arange(len(at))[:, None]
    profile = np.empty(0)
    k_max = min(n - 1, 32 if until is not None else n - 1)
    while True:
        lags = np.arange(len(profile), k_max + 1)
        sides = []
        for sign in (-1, 1):
            j = at[:, None] + sign * lags[None, :]
            ok = (j >= 0) & (j < n)
            sides.append(np.where(ok, norm[rows_idx, np.clip(j, 0, n - 1)], np.nan))
        profile = np.concatenate([profile, _column_medians(np.concatenate(sides, axis=0))])
        part = profile[len(profile) - len(lags):]
        if k_max >= n - 1 or (until is not None and np.nanmax(part, initial=-np.inf) >= until):
            return profile
        k_max = min(n - 1, 2 * k_max)


def _column_medians(values: np.ndarray) -> np.ndarray:
    """The median of each column over its non-NaN entries (NaN for a column with none): NaN
    sorts last, so the middle of the first `count` entries is the median."""
    ordered = np.sort(values, axis=0)
    count = np.count_nonzero(~np.isnan(values), axis=0)
    lo = np.take_along_axis(ordered, np.maximum((count - 1) // 2, 0)[None, :], axis=0)[0]
    hi = np.take_along_axis(ordered, np.maximum(count // 2, 0)[None, :], axis=0)[0]
    return np.where(count > 0, (lo + hi) / 2, np.nan)


def dip_window(rows: np.ndarray, at: np.ndarray) -> WindowChoice:
    """The ``dip`` rule's window for the database whose self-difference rows these are
    (module doc)."""
    n = np.asarray(rows).shape[1] if np.ndim(rows) == 2 else 0
    profile = self_difference_profile(rows, at, until=DIP_LEVEL)
    whole = max(2 * (n - 1), 2)  # every frame of the row, for every frame
    if len(profile) < 2 or np.isnan(profile[1:]).all():
        return WindowChoice(whole, None, len(at), "no sampled row of the database's "
                            "self-difference has a positive median (constant rows, or a "
                            "distance that is not positive)")
    reached = np.flatnonzero(profile[1:] >= DIP_LEVEL)
    if not len(reached):
        return WindowChoice(whole, None, len(at),
                            f"the self-difference never reaches {DIP_LEVEL} of a typical "
                            f"difference within the {n} database frames (the database is "
                            "shorter than its own dip)")
    h = int(reached[0]) + 1
    return WindowChoice(min(2 * DIP_FACTOR * h, whole), h, len(at), None,
                        [float(p) for p in profile[:h + 1]], capped=2 * DIP_FACTOR * h > whole)
