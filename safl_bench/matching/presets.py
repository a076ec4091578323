"""Named matcher presets: whole sets of the shared matcher's settings, each with its source.

``safl-bench run --matcher-preset NAME`` picks one (default ``paper``), ``--matcher KEY=VALUE``
refines it, and ``safl-bench list matchers`` prints them all. A preset is an
`EvaluationConfig`: the sequence matcher's `MatcherConfig` (whose ``preset`` field carries the
name into every record) and the evaluation-level settings. Every record holds all of the
settings; `label` names them for tables ("paper", "authors+enhance_window=0").

``paper`` - the paper as printed: Table I (d_s = 10; V from 0.8 to 1.1 by 0.1) and Eq. 5-7
(`safl_bench.matching.matcher`, whose docstring says how each gap is filled: the contrast-enhancement
window of 10 frames, centred, is OpenSeqSLAM's, since the paper gives none). These are the
`MatcherConfig` defaults, unchanged since before the presets.

``authors`` - the paper's authors' public code, repository CNN-GAN/Top-Mapping, read for this
(not copied): ``enhanceContrast`` and ``getMatches`` in src/util/utils.py (the matcher of the
learned features), the flags of parameters.py, and ``Seq_LiDAR`` in
src/third_function/pyseqslam/seq_lidar.py (the LiDAR evaluation and its PR curve). Setting by
setting:

- ``enhance_window=20``, centred: parameters.py ``enhance`` = 20; ``enhanceContrast(D, enhance)``
  normalises each frame by the rows ``i - enhance/2 .. i + enhance/2`` of the database axis,
  clipped, ``std(ddof=1)`` - the same window as ``enhance_mode="centred"`` here. (Some of their
  plotting scripts, e.g. src/plot/ULFL/plotDraw_2d.py, call it with 30 instead.)
- ``shift=False`` (QUIRK): ``enhanceContrast`` returns the z-scores with
  ``return DD-np.min(np.min(DD))`` commented out, so S is negative for good matches.
- ``ds=10``, velocities ``v_min=0.8 .. v_max=1.2`` by 0.1, inclusive (five): parameters.py
  ``v_ds`` = 10, ``vmin`` = 0.8, ``vmax`` = 1.2; ``getMatches`` takes
  ``arange(int(vmin*v_ds), int(vmax*v_ds)+1) / v_ds`` (its ``vskip`` flag is not used).
- ``trajectory="centred"``: ``getMatches`` starts the trajectory of query N at
  ``N - v_ds/2`` and runs it over ``v_ds + 1`` queries (``n_start = N + 1 - v_ds/2``, 1-based).
- ``offset_rounding="floor_start"``: the trajectory's k-th point is at database row
  ``s + floor(k v)`` (``idx_add``), and the match reported is ``min_idx + v_ds/2``, the start
  row plus half the length, whatever v.
- ``edge_queries="skip"``: ``for N in range(v_ds/2, DD.shape[1]-v_ds/2)``: the first and the
  last ds/2 queries get no match (NaN there, index -1 here).
- ``out_of_range="exclude"``: a row of +inf is appended "to penalize running out of data", and
  row indices past it are clipped onto it (``y[y>y_max]=y_max``).
- ``score="inverse"`` (QUIRK): ``match = [min_idx + v_ds/2, 1. / min_value]`` with
  ``min_value`` the trajectory SUM; the higher, the more confident (the PR curve thresholds it).
  With the unshifted z-scores a strong match has S < 0, so 1/S < 0 ranks it below every
  positive S: the strongest matches get the lowest confidence.
- ``capped_match=1`` (QUIRK): ``if match[1] > 1: match = 1.0`` assigns 1.0 to BOTH columns, so
  every query with 0 <= S < 1 reports database frame 1 at the top confidence 1.
- ``ratio_window=10``: parameters.py ``Rwindow`` = 10 (``getMatches`` computes the second best
  S outside it but no longer uses it: the ratio line is commented out); unused by "inverse".
- ``trim_queries=20`` (evaluation level): ``Seq_LiDAR`` builds the PR curve from
  ``results.matches[(int(args.v_ds)+10) : n - args.v_ds - 10]``: ds + 10 = 20 queries dropped at
  each end. (This is not tied to ``ds``: with ``--matcher ds=N`` set it as well.)
- ``max_frames=200`` (evaluation level): parameters.py ``test_len`` = 200 and ``frame_skip`` = 4;
  the poses and images are read as ``[0 : test_len*frame_skip : frame_skip]``, database and
  queries alike: the first 200 of every 4th frame (this project's tasks already take every 4th
  frame, so the first 200 task frames are theirs).

Not part of the preset: ``dtype`` stays float32 (theirs is numpy's float64; ``--matcher
dtype=float64`` for their arithmetic); their difference is the Euclidean norm (``Euclidean`` in
utils.py), not Eq. 4's square, which belongs to the method (``distance``), not to the matcher;
their recall is read at >= 99 % precision (`metrics.evaluate(precision_level=0.99)`), while
records report exactly 100 %; a window with zero spread divides by zero there (0 here).

``openseqslam`` - Milford & Wyeth's SeqSLAM as released in OpenSeqSLAM (Sünderhauf's MATLAB:
``findSingleMatch`` in doFindMatches.m; its defaults and contrast enhancement as in the Python
port the authors ship, src/third_function/pyseqslam/src/parameters.py ``defaultParameters`` and
seqslam.py ``SeqSLAM.enhanceContrast``): ``ds = 10``; velocities ``move_min:move_max`` over ds,
inclusive, with vmin 0.8 and vmax 1.2 (five); contrast enhancement over ``R = 10`` database
frames, centred, then shifted so that its minimum is 0; the trajectory centred on the query
(``n_start = N - ds/2``), anchored at its start with ``floor(k v)``, the match reported at
start + ds/2; no match for the first and last ds/2 queries; +inf past the database; the score
is the best S over the best S farther than ``Rwindow/2 = 5`` frames from the match
(``min_value / min_value_2nd``; MATLAB's window is inclusive, the port's drops one frame).
"""

from __future__ import annotations

import dataclasses
import difflib
import json
from dataclasses import dataclass
from typing import Any

from safl_bench.errors import ConfigError
from safl_bench.matching.matcher import MatcherConfig
from safl_bench.matching.settings import EVALUATION_SETTINGS, EvaluationConfig

#: The preset a run uses when none is named.
DEFAULT = "paper"


@dataclass(frozen=True)
class Preset:
    """A named set of matcher settings and the one line that says where it comes from."""

    name: str
    description: str
    config: EvaluationConfig


def _preset(name: str, description: str, max_frames: int | None = None, trim_queries: int = 0,
            **matcher: Any) -> Preset:
    return Preset(name, description, EvaluationConfig(MatcherConfig(preset=name, **matcher),
                                                      max_frames=max_frames,
                                                      trim_queries=trim_queries))


PRESETS: dict[str, Preset] = {p.name: p for p in (
    _preset("paper", "the paper: Table I and Eq. 5-7 as printed (OpenSeqSLAM's 10-frame "
                     "enhancement window, where the paper gives none); the default"),
    _preset("authors", "the paper's authors' public code (CNN-GAN/Top-Mapping utils.py, "
                       "parameters.py, seq_lidar.py), quirks included: unshifted z-scores, "
                       "1/S capped at 1",
            enhance_window=20, shift=False, v_max=1.2, trajectory="centred",
            offset_rounding="floor_start", edge_queries="skip", score="inverse",
            capped_match=1, max_frames=200, trim_queries=20),
    _preset("openseqslam", "Milford & Wyeth's SeqSLAM as released in OpenSeqSLAM: ratio to the "
                           "best S outside 10 frames, centred trajectory, V 0.8-1.2",
            v_max=1.2, trajectory="centred", offset_rounding="floor_start",
            edge_queries="skip", score="ratio"),
)}


def names() -> list[str]:
    """The presets' names, the default first."""
    return list(PRESETS)


def get(name: str) -> Preset:
    """The preset called `name`; ConfigError with "did you mean" and the list otherwise."""
    try:
        return PRESETS[name]
    except (KeyError, TypeError):
        close = difflib.get_close_matches(str(name), PRESETS, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise ConfigError(f"unknown matcher preset {name!r}; {hint}presets: "
                          f"{', '.join(PRESETS)} (safl-bench list matchers)") from None


#: Settings `configure` (``--matcher KEY=VALUE``) may change, in the order tables list them.
SETTINGS: tuple[str, ...] = tuple(
    f.name for f in dataclasses.fields(MatcherConfig) if f.name not in ("method", "preset")
) + EVALUATION_SETTINGS


#: One line per setting, for `safl-bench list matchers` (the module docstrings say more).
SETTING_HELP: dict[str, str] = {
    "ds": "trajectory length: ds + 1 queries (Table I d_s)",
    "v_min": "slowest trajectory velocity (Table I V_min)",
    "v_max": "fastest trajectory velocity (Table I V_max)",
    "v_step": "velocity step (Table I V_step)",
    "v_inclusive": "whether v_max itself is one of the velocities",
    "enhance_window": "contrast-enhancement window in database frames (Eq. 5; 0: off)",
    "enhance_mode": "that window centred on the frame, or ending at it (causal)",
    "trajectory": "trajectory ending at the query (causal, Eq. 6) or centred on it",
    "edge_queries": "queries without a full trajectory: a shorter one, or no match (skip)",
    "out_of_range": "trajectory points past the database: drop the candidate, or clip",
    "score": "query score: lowest S (min), S over the best S elsewhere (ratio), capped 1/S",
    "ratio_window": "frames around the match that the ratio's second best S may not use",
    "dtype": "arithmetic of the enhancement and the search",
    "shift": "shift the enhanced matrix so that its minimum is 0",
    "offset_rounding": "trajectory points: V u rounded about the query, or floor(V k) from its start",
    "capped_match": "inverse score: the frame reported when 1/S is capped (null: the match)",
    "max_frames": "only the first N task frames, database and queries (null: all)",
    "trim_queries": "queries left out of the metrics at each end of the sequence",
}


def configure(name: str = DEFAULT, changes: dict[str, Any] | None = None,
              *, flag: str = "--matcher") -> EvaluationConfig:
    """Preset `name` with `changes` (setting -> value) on top; the name stays recorded as the
    ``preset`` setting, the changed values beside it. An unknown setting is a ConfigError that
    names the valid ones (`flag` names the option in the message)."""
    base = get(name).config
    changes = dict(changes or {})
    unknown = sorted(set(changes) - set(SETTINGS))
    if unknown:
        raise ConfigError(f"{flag}: unknown setting(s) {unknown}; valid: {sorted(SETTINGS)}")
    matcher = {k: v for k, v in changes.items() if k not in EVALUATION_SETTINGS}
    evaluation = {k: v for k, v in changes.items() if k in EVALUATION_SETTINGS}
    try:
        sequence = dataclasses.replace(base.sequence, **matcher)
    except TypeError as exc:  # a value of a type the dataclass cannot take
        raise ConfigError(f"{flag}: {exc}") from None
    return dataclasses.replace(base, sequence=sequence, **evaluation)


def settings(config: EvaluationConfig) -> dict[str, Any]:
    """Every setting of `config` by name (`SETTINGS`, then ``preset``), flat."""
    out = {name: getattr(config.sequence, name) for name in SETTINGS
           if name not in EVALUATION_SETTINGS}
    out.update({name: getattr(config, name) for name in EVALUATION_SETTINGS})
    out["preset"] = config.sequence.preset
    return out


def format_value(value: Any) -> str:
    """A setting's value as the command line takes it (``--matcher KEY=VALUE``)."""
    return value if isinstance(value, str) else json.dumps(value)


def changes(config: EvaluationConfig) -> dict[str, Any]:
    """The settings in which `config` differs from the preset it names ({} for an unknown
    preset name, e.g. one from a newer version)."""
    preset = PRESETS.get(config.sequence.preset)
    if preset is None:
        return {}
    mine, base = settings(config), settings(preset.config)
    return {k: v for k, v in mine.items() if k != "preset" and v != base[k]}


def label(config: EvaluationConfig | dict[str, Any]) -> str:
    """How tables name a record's matcher settings: the preset, then what was changed on top,
    e.g. "paper", "paper+enhance_window=0", "authors+ds=5,score=min". Takes a config or a
    record's ``matcher`` field; a record made before the presets is "paper"; a field that
    cannot be read is "unreadable". Never raises."""
    if not isinstance(config, EvaluationConfig):
        try:
            config = EvaluationConfig.from_dict(config)
        except (ConfigError, TypeError):
            return "unreadable"
    diff = changes(config)
    name = config.sequence.preset
    if not diff:
        return name
    return name + "+" + ",".join(f"{k}={format_value(v)}" for k, v in diff.items())
