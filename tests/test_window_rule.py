"""The ``dip`` rule for Eq. 5's enhancement window: measured on the database's self-difference,
recorded per cell, with a stated fallback where the dip cannot be measured."""

from __future__ import annotations

import numpy as np
import pytest

from safl_bench import matcher_presets
from safl_bench.errors import DataError
from safl_bench.evaluation import evaluate_method
from safl_bench.evaluation.cell import choose_window
from safl_bench.groundtruth import GroundTruth
from safl_bench.matching import MatcherConfig, match
from safl_bench.matching.window import (
    DIP_FACTOR,
    DIP_LEVEL,
    DIP_ROWS,
    dip_window,
    sample_rows,
    self_difference_profile,
)
from safl_bench.method import Method


def dip_rows(n: int, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Self-difference rows of a database whose frames differ as 1 - exp(-lag / length)."""
    at = sample_rows(n)
    lag = np.abs(np.arange(n)[None, :] - at[:, None])
    return 1.0 - np.exp(-lag / length), at


def test_the_window_is_factor_times_the_dip_width() -> None:
    rows, at = dip_rows(400, 5.0)
    choice = dip_window(rows, at)
    # p(k) = (1 - e^{-k/5}) / median ≈ 1 - e^{-k/5} (the median row value is ~1): first
    # lag at DIP_LEVEL of the row median
    profile = self_difference_profile(rows, at)
    h = int(np.flatnonzero(profile[1:] >= DIP_LEVEL)[0]) + 1
    assert choice.half_width == h and 8 <= h <= 14
    assert choice.window == 2 * DIP_FACTOR * h
    assert choice.fallback is None and choice.rows == DIP_ROWS
    assert choice.profile[0] == 0.0 and choice.profile[-1] >= DIP_LEVEL
    wider = dip_window(*dip_rows(400, 10.0))
    assert wider.half_width is not None and wider.half_width > h
    assert "dip half-width" in choice.describe()


def test_a_database_shorter_than_its_dip_takes_the_whole_row() -> None:
    rows, at = dip_rows(12, 50.0)  # the frames never stop looking alike
    choice = dip_window(rows, at)
    assert choice.window == 2 * 11 and choice.capped and choice.fallback is None
    assert choice.to_dict()["capped"] is True
    assert "capped at the whole database" in choice.describe()
    assert not dip_window(*dip_rows(400, 5.0)).capped


def test_constant_rows_fall_back_and_nan_is_refused() -> None:
    at = sample_rows(30)
    choice = dip_window(np.zeros((len(at), 30)), at)
    assert choice.half_width is None and "positive median" in str(choice.fallback)
    bad = np.ones((len(at), 30))
    bad[0, 3] = np.nan
    with pytest.raises(DataError, match="1 NaN or infinite"):
        dip_window(bad, at)
    with pytest.raises(DataError, match="at least one frame"):
        sample_rows(0)


class LineMethod(Method):
    """Frames along a line: descriptor = a smooth function of the frame index."""

    name, version, input_kind = "line_method", "1", "topview"

    def describe(self, maps: object) -> np.ndarray:
        idx = np.asarray(maps, dtype=np.float64)
        freqs = np.arange(1, 17)[None, :] / 40.0
        return np.concatenate([np.sin(idx[:, None] * freqs), np.cos(idx[:, None] * freqs)],
                              axis=1).astype(np.float32)


def test_the_paper_preset_chooses_and_records_the_window_per_cell() -> None:
    n = 120
    xy = np.c_[np.arange(n, dtype=float), np.zeros(n)]
    t = np.arange(n, dtype=float)
    truth = GroundTruth(xy, xy, t, t, tp_radius=1.0, fp_radius=1.0)
    method = LineMethod()
    paper = matcher_presets.get("paper").config
    ev = evaluate_method(method, np.arange(n), np.arange(n), truth, config=paper)
    assert ev.window is not None and ev.window.fallback is None
    assert ev.window == choose_window(method, method.describe(np.arange(n)))
    D = method.distance(method.describe(np.arange(n)), method.describe(np.arange(n)))
    same = match(D, MatcherConfig(enhance_window=ev.window.window))
    np.testing.assert_array_equal(ev.matches["sequence"].index, same.index)
    np.testing.assert_array_equal(ev.matches["sequence"].score, same.score)
    assert ev.matches["sequence"].enhance_window == ev.window.window
    assert ev.matches["single_frame"].enhance_window == 0
    fixed = evaluate_method(method, np.arange(n), np.arange(n), truth)
    assert fixed.window is None and fixed.matches["sequence"].enhance_window == 10


def test_a_window_given_on_the_command_line_is_a_fixed_window() -> None:
    off = matcher_presets.configure("paper", {"enhance_window": 0}).sequence
    assert off.enhance_rule == "fixed" and off.enhance_window == 0 and not off.needs_window
    assert matcher_presets.label(matcher_presets.configure("paper", {"enhance_window": 30})) \
        == "paper+enhance_window=30,enhance_rule=fixed"
    assert matcher_presets.label(matcher_presets.configure("paper", {"enhance_window": 0})) \
        == "paper+enhance_rule=fixed,enhance_window=0"
    assert matcher_presets.configure("paper-r10", {"enhance_rule": "dip",
                                                   "enhance_window": 0}).sequence.needs_window


def test_a_retrieval_record_follows_a_change_of_the_sequence_matcher_without_a_recompute() -> None:
    import dataclasses

    from record_factory import make_record

    from safl_bench.evaluation import EvaluationConfig
    from safl_bench.records import MethodInfo
    from safl_bench.results.derive import NotDerivableError, relabel_retrieval

    old = make_record("map_closures")
    old = dataclasses.replace(old, matcher=EvaluationConfig().to_dict(),
                              method=MethodInfo(name="map_closures", version="1", kind="retrieval"))
    paper = matcher_presets.get("paper").config.to_dict()
    new = relabel_retrieval(old, paper)
    assert matcher_presets.label(new.matcher) == "paper" and new.results == old.results
    assert new.derived_from is not None and "relabelled paper-r10 -> paper" in new.derived_from.note
    trimmed = matcher_presets.configure("paper", {"trim_queries": 3}).to_dict()
    with pytest.raises(NotDerivableError, match="differ beyond the sequence matcher"):
        relabel_retrieval(old, trimmed)
    with pytest.raises(NotDerivableError, match="not a retrieval method"):
        relabel_retrieval(make_record("sad"), paper)
