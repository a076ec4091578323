"""The matcher settings of an evaluation: both matching modes and the evaluation-level ones.

`EvaluationConfig` is what every record's ``matcher`` field holds and what a preset
(`safl_bench.matching.presets`) names: the sequence matcher's `MatcherConfig` (the single-frame
settings follow from it) and evaluation-level settings that reproduce the authors' public
code, all off by default (the paper's protocol): ``max_frames``, ``trim_queries`` and
``distance`` (`safl_bench.evaluation.cell`'s docstring says what each does), and ``truth_at``,
where a noisy query's true places are measured from (`safl_bench.tasks.task.Task.truth_for`),
and ``candidates``/``index``, the opt-in candidate search (`safl_bench.matching.candidates`).
It lives with the matcher, not with the evaluation that reads it, so that the presets need
nothing of a later stage.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from safl_bench.errors import ConfigError
from safl_bench.matching.matcher import MatcherConfig

#: The matching modes every evaluation reports, in the order tables show them.
MODES = ("sequence", "single_frame")


#: Evaluation-level settings (`EvaluationConfig` fields other than the matcher), as recorded.
EVALUATION_SETTINGS = ("max_frames", "trim_queries", "distance", "truth_at", "candidates", "index")

#: The candidate-search settings (`safl_bench.matching.candidates`): recorded only when
#: ``candidates`` is set, so an exact cell's record reads as it did before they existed.
CANDIDATE_SETTINGS = ("candidates", "index")

#: How descriptors may be compared (`EvaluationConfig.distance`).
DISTANCES = ("method", "euclidean")

#: The candidate search's indexes (`safl_bench.matching.candidates.INDEXES`).
INDEXES = ("flat", "ivf")

#: Where a query's true places are measured from (`EvaluationConfig.truth_at`): the pose of its
#: frame, or the noisy viewpoint its view was made at (the same for clean queries).
TRUTH_AT = ("frame", "viewpoint")

#: Presets renamed since records were made: a record whose matcher settings name the old name
#: and lack the ``distance`` setting (every record made before it existed) was made with the
#: settings the new name now holds, and is read as that preset (`EvaluationConfig.from_dict`).
#: "authors" followed the repository's later code until the paper-era preset took its name.
RENAMED_PRESETS = {"authors": "authors-2018"}


@dataclass(frozen=True)
class EvaluationConfig:
    """The matcher settings of an evaluation (recorded with every result).

    max_frames: use only the first N frames of the task (of its every-`step`-th frames) as
    database AND queries (None: all). trim_queries: leave the first and the last N queries out
    of the metrics (they are still matched, and their trajectories use their neighbours).
    distance: "method" (the method's own difference) or "euclidean" (plain L2 between the
    descriptors; module docstring). candidates: None (the exact matcher) or K, the sequence
    search through each query's K nearest frames of `index` ("flat" exact, "ivf" approximate). truth_at: "frame" (a query's true places lie within the
    radius of its frame's pose, the paper protocol's default) or "viewpoint" (of the noisy
    viewpoint its view shows, `Task.truth_for`).
    """

    sequence: MatcherConfig = field(default_factory=MatcherConfig)
    max_frames: int | None = None
    trim_queries: int = 0
    distance: str = "method"
    truth_at: str = "frame"
    candidates: int | None = None
    index: str = "flat"

    def __post_init__(self) -> None:
        n = self.max_frames
        if n is not None and (not isinstance(n, int) or isinstance(n, bool) or n < 1):
            raise ConfigError(f"max_frames must be null (all frames) or an integer >= 1, got {n!r}")
        t = self.trim_queries
        if not isinstance(t, int) or isinstance(t, bool) or t < 0:
            raise ConfigError(f"trim_queries must be an integer >= 0, got {t!r}")
        if self.distance not in DISTANCES:
            raise ConfigError(f"distance must be one of {list(DISTANCES)}, got {self.distance!r}")
        if self.truth_at not in TRUTH_AT:
            raise ConfigError(f"truth_at must be one of {list(TRUTH_AT)}, got {self.truth_at!r}")
        k = self.candidates
        if k is not None and (not isinstance(k, int) or isinstance(k, bool) or k < 1):
            raise ConfigError(f"candidates must be null (the exact matcher) or a whole number of "
                              f"frames >= 1, got {k!r}")
        if self.index not in INDEXES:
            raise ConfigError(f"index must be one of {list(INDEXES)}, got {self.index!r}")

    @property
    def single_frame(self) -> MatcherConfig:
        """The no-sequence baseline (`matching.single_frame`'s settings: one frame, no contrast
        enhancement), scored like the sequence matcher, except that the authors' capped 1/S
        ("inverse", a quirk of their sequence matcher: on raw differences below 1 it would cap
        every query and, with ``capped_match``, answer frame 1 for all) becomes "min", its
        ranking without the quirks. The recorded ``single_frame`` settings say which."""
        seq = self.sequence
        if seq.score == "inverse":
            return MatcherConfig(method="single_frame", ds=0, enhance_window=0, score="min",
                                 ratio_window=seq.ratio_window, dtype=seq.dtype, preset=seq.preset)
        return MatcherConfig(method="single_frame", ds=0, enhance_window=0, score=seq.score,
                             ratio_window=seq.ratio_window, dtype=seq.dtype, shift=seq.shift,
                             preset=seq.preset)

    def matcher(self, mode: str) -> MatcherConfig:
        return self.sequence if mode == "sequence" else self.single_frame

    def to_dict(self) -> dict[str, Any]:
        """What records store: each mode's matcher settings, and the evaluation-level ones."""
        out: dict[str, Any] = {mode: self.matcher(mode).to_dict() for mode in MODES}
        out["evaluation"] = {name: getattr(self, name) for name in EVALUATION_SETTINGS
                             if self.candidates is not None or name not in CANDIDATE_SETTINGS}
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> EvaluationConfig:
        """The config a record's ``matcher`` field describes (`to_dict`'s inverse; the
        single-frame settings follow from the sequence ones). A record made before a setting
        existed is read with that setting's default, which is what its code did, and one made
        under a preset name since renamed is read as the renamed preset (`RENAMED_PRESETS`)."""
        if not isinstance(data, dict) or not isinstance(data.get("sequence"), dict):
            raise ConfigError(f"matcher settings need a 'sequence' mapping, got {data!r}")
        extra = data.get("evaluation", {})
        if not isinstance(extra, dict) or set(extra) - set(EVALUATION_SETTINGS):
            raise ConfigError(f"evaluation settings: expected keys of {list(EVALUATION_SETTINGS)}, "
                              f"got {extra!r}")
        sequence = data["sequence"]
        if "distance" not in extra and sequence.get("preset") in RENAMED_PRESETS:
            sequence = {**sequence, "preset": RENAMED_PRESETS[sequence["preset"]]}
        return cls(MatcherConfig.from_dict(sequence), **extra)


def same_settings(recorded: Any, wanted: dict[str, Any]) -> bool:
    """Whether a record's ``matcher`` field holds the settings `wanted` (an
    `EvaluationConfig.to_dict()`), reading settings the record predates as their defaults: a
    record made before the presets existed is the "paper" preset. Never raises."""
    if recorded == wanted:
        return True
    try:
        return EvaluationConfig.from_dict(recorded).to_dict() == wanted
    except (ConfigError, TypeError):
        return False
