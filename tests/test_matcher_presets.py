"""Matcher presets: paper = the defaults as before, each authors quirk on hand-made matrices,
evaluation-level settings, --matcher-preset on the command line and `list matchers`."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from safl_bench import matcher_presets, matching, tasks
from safl_bench.cli import main
from safl_bench.errors import ConfigError
from safl_bench.evaluation import (
    EvaluationConfig,
    difference_matrix,
    evaluate_method,
    same_settings,
)
from safl_bench.groundtruth import GroundTruth
from safl_bench.mapconfig import MapConfig
from safl_bench.matching import MatcherConfig
from safl_bench.matching_loop import ref_enhance
from safl_bench.method import Method

#: MatcherConfig().to_dict() before the presets existed: records made then hold exactly this.
OLD_DEFAULTS = {
    "method": "seqslam", "ds": 10, "v_min": 0.8, "v_max": 1.1, "v_step": 0.1,
    "v_inclusive": True, "enhance_window": 10, "enhance_mode": "centred", "trajectory": "causal",
    "edge_queries": "shorten", "out_of_range": "exclude", "score": "min", "ratio_window": 10,
    "dtype": "float32",
}
OLD_SINGLE = {**OLD_DEFAULTS, "method": "single_frame", "ds": 0, "enhance_window": 0}


def authors(**changes: object) -> MatcherConfig:
    return matcher_presets.configure("authors", dict(changes)).sequence


# --------------------------------------------------------------------------- paper


def test_paper_r10_preset_is_the_old_defaults() -> None:
    old = matcher_presets.get("paper-r10").config
    assert old == EvaluationConfig()
    assert old.sequence == MatcherConfig()
    recorded = old.to_dict()
    assert {k: recorded["sequence"][k] for k in OLD_DEFAULTS} == OLD_DEFAULTS
    assert {k: recorded["single_frame"][k] for k in OLD_SINGLE} == OLD_SINGLE
    assert recorded["sequence"]["preset"] == "paper-r10"
    assert recorded["sequence"]["enhance_rule"] == "fixed"
    assert recorded["evaluation"] == {"max_frames": None, "trim_queries": 0, "distance": "method",
                                      "truth_at": "frame"}
    assert old.sequence.velocities().tolist() == [0.8, 0.9, 1.0, 1.1]


def test_paper_preset_is_paper_r10_with_the_dip_rule() -> None:
    paper = matcher_presets.get("paper").config
    assert matcher_presets.DEFAULT == "paper"
    assert dataclasses.replace(paper.sequence, enhance_rule="fixed", enhance_window=10,
                               preset="paper-r10") == MatcherConfig()
    assert paper.sequence.needs_window and not paper.single_frame.needs_window
    assert matcher_presets.label(paper) == "paper"


def test_records_made_before_the_rule_read_as_paper_r10() -> None:
    """A record made as "paper" before the rule (or before the presets) is the fixed window:
    it is read as paper-r10 and never as today's paper."""
    old = {"sequence": OLD_DEFAULTS, "single_frame": OLD_SINGLE}
    named = {"sequence": {**OLD_DEFAULTS, "preset": "paper"},
             "single_frame": {**OLD_SINGLE, "preset": "paper"}}
    for recorded in (old, named):
        assert same_settings(recorded, EvaluationConfig().to_dict())
        assert not same_settings(recorded, matcher_presets.get("paper").config.to_dict())
        assert matcher_presets.label(recorded) == "paper-r10"
    changed = {"sequence": {**OLD_DEFAULTS, "enhance_window": 0}, "single_frame": OLD_SINGLE}
    assert not same_settings(changed, EvaluationConfig().to_dict())
    assert matcher_presets.label(changed) == "paper-r10+enhance_window=0"
    assert not same_settings({"ds": 10}, EvaluationConfig().to_dict())
    assert matcher_presets.label({"ds": 10}) == "unreadable"
    new = matcher_presets.get("paper").config.to_dict()
    assert EvaluationConfig.from_dict(new) == matcher_presets.get("paper").config


def test_paper_matches_are_those_of_the_window_it_is_given() -> None:
    D = np.random.default_rng(3).random((40, 50)).astype(np.float32)
    paper = matcher_presets.get("paper").config.sequence
    a = matching.match(D, paper, keep_S=True, enhance_window=24)
    b = matching.match(D, MatcherConfig(enhance_window=24), keep_S=True)
    for name in ("index", "score", "best_s", "velocity", "n_terms", "S"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.enhance_window == 24
    with pytest.raises(ConfigError, match="takes its window from the database"):
        matching.match(D, paper)
    with pytest.raises(ConfigError, match="must be 0"):
        dataclasses.replace(paper, enhance_window=10)
    with pytest.raises(ConfigError, match="fixed window of 10"):
        matching.match(D, MatcherConfig(), enhance_window=24)


# --------------------------------------------------------------------------- authors quirks


def test_authors_preset_settings() -> None:
    cfg = matcher_presets.get("authors").config
    seq = cfg.sequence
    assert (seq.enhance_window, seq.enhance_mode, seq.shift) == (30, "centred", False)
    assert (seq.ds, seq.trajectory, seq.offset_rounding) == (10, "centred", "floor_start")
    assert (seq.edge_queries, seq.out_of_range) == ("skip", "exclude")
    assert (seq.score, seq.capped_match) == ("inverse", 1)
    assert (cfg.max_frames, cfg.trim_queries, cfg.distance) == (300, 5, "euclidean")
    later = matcher_presets.get("authors-2018").config
    assert later.sequence == dataclasses.replace(seq, enhance_window=20, preset="authors-2018")
    assert (later.max_frames, later.trim_queries, later.distance) == (200, 20, "method")
    sad = matcher_presets.get("authors-sad").config
    assert (sad.sequence.ds, sad.sequence.enhance_window, sad.sequence.shift) == (40, 10, True)
    assert (sad.max_frames, sad.trim_queries, sad.distance) == (300, 20, "method")
    # getMatches: arange(int(vmin*ds), int(vmax*ds)+1) / ds with vmin 0.8, vmax 1.2: the same doubles
    theirs = np.arange(int(0.8 * 10), int(1.2 * 10) + 1).astype(float) / 10
    assert seq.velocities().tolist() == theirs.tolist()


def test_unshifted_enhancement_keeps_negative_z_scores() -> None:
    D = np.random.default_rng(0).random((6, 30))
    shifted = matching.enhanced_matrix(D, MatcherConfig(dtype="float64"))
    raw = matching.enhanced_matrix(D, MatcherConfig(dtype="float64", shift=False))
    assert shifted.min() == 0.0 and raw.min() < 0
    np.testing.assert_allclose(shifted, raw - raw.min())
    np.testing.assert_allclose(raw, ref_enhance(D, 10, "centred"), atol=1e-9)


def test_inverse_score_ranks_a_negative_S_below_every_positive_one_and_caps_at_1() -> None:
    # one database frame wins each row; no enhancement and no trajectory, so S is the entry
    D = np.array([[-2.0, 5, 5], [3.0, 5, 5], [0.5, 5, 5], [50.0, 60, 60]])
    cfg = MatcherConfig(ds=0, enhance_window=0, shift=False, score="inverse", dtype="float64")
    res = matching.match(D, cfg)
    np.testing.assert_allclose(res.confidence, [1 / -2.0, 1 / 3.0, 1.0, 1 / 50.0])
    # the strongest match (S = -2) is the least confident; S = 0.5 is capped to the top, 1
    assert list(np.argsort(-res.confidence)) == [2, 1, 3, 0]
    assert res.index.tolist() == [0, 0, 0, 0]
    # ... and with the authors' `match = 1.0`, the capped query answers database frame 1
    quirk = matching.match(D, MatcherConfig(ds=0, enhance_window=0, shift=False, score="inverse",
                                            capped_match=1, dtype="float64"))
    assert quirk.index.tolist() == [0, 0, 1, 0]
    np.testing.assert_array_equal(quirk.confidence, res.confidence)
    # the "min" score ranks the same matches strongest first
    assert list(np.argsort(matching.match(D, MatcherConfig(ds=0, enhance_window=0)).score)) == [0, 2, 1, 3]


def test_inverse_score_uses_the_trajectory_sum() -> None:
    # three queries on the diagonal at 0.5 each: mean 0.5 (would be capped), sum 1.5 (is not)
    D = np.full((3, 8), 9.0)
    D[[0, 1, 2], [2, 3, 4]] = 0.5
    cfg = MatcherConfig(ds=2, v_min=1.0, v_max=1.0, enhance_window=0, shift=False,
                        trajectory="centred", edge_queries="skip", score="inverse", capped_match=1,
                        dtype="float64")
    res = matching.match(D, cfg)
    assert res.index.tolist() == [-1, 3, -1]
    assert res.confidence[1] == pytest.approx(1 / 1.5)


def test_skip_with_the_centred_trajectory_leaves_ds_over_2_queries_at_each_end() -> None:
    D = np.random.default_rng(1).random((20, 30))
    res = matching.match(D, authors(ds=4, enhance_window=6))
    assert (res.index[:2] == -1).all() and (res.index[-2:] == -1).all()
    assert (res.index[2:-2] >= 0).all() and np.isinf(res.score[:2]).all()


def test_floor_from_start_offsets_and_the_reported_frame() -> None:
    cfg = MatcherConfig(trajectory="centred", offset_rounding="floor_start", v_max=1.2)
    offs = cfg.offsets()
    assert offs[0].tolist() == [-5, -5, -4, -3, -2, -1, -1, 0, 1, 2, 3]  # V = 0.8
    assert offs[2].tolist() == list(range(-5, 6))  # V = 1
    assert offs[4].tolist() == [-5, -4, -3, -2, -1, 1, 2, 3, 4, 5, 7]  # V = 1.2
    # a planted route at V = 0.8 from database frame 30: reported at 30 + ds/2 = 35, although the
    # route passes frame 34 at the query itself
    D = np.ones((25, 80))
    T = 12
    for k in range(11):
        D[T - 5 + k, 30 + math.floor(0.8 * k)] = 0.0
    res = matching.match(D, MatcherConfig(trajectory="centred", offset_rounding="floor_start",
                                          enhance_window=0, dtype="float64"))
    assert res.index[T] == 35 and res.velocity[T] == pytest.approx(0.8)
    half_up = matching.match(D, MatcherConfig(trajectory="centred", enhance_window=0, dtype="float64"))
    assert half_up.index[T] != 35


def _ref_authors(D: np.ndarray, ds: int, window: int) -> tuple[np.ndarray, np.ndarray]:
    """The authors' matcher as described in matcher_presets (written from that description):
    unshifted z-scores, the trajectory of query N from N - ds/2 over ds + 1 queries through
    s + floor(k v), +inf past the database, 1/S_sum capped at 1 (then frame 1)."""
    nq, ndb = D.shape
    Dh = ref_enhance(D, window, "centred")
    vels = np.arange(8, 13) / 10
    index, conf = np.full(nq, -1), np.full(nq, -np.inf)
    for N in range(ds // 2, nq - ds // 2):
        score = np.full(ndb, np.inf)
        for s in range(ndb):
            for v in vels:
                rows = [s + math.floor(k * v) for k in range(ds + 1)]
                if rows[-1] < ndb:
                    score[s] = min(score[s], sum(Dh[N - ds // 2 + k, r] for k, r in enumerate(rows)))
        best = int(np.argmin(score))
        inv = 1.0 / score[best]
        index[N], conf[N] = (1, 1.0) if inv > 1 else (best + ds // 2, inv)
    return index, conf


def test_authors_matcher_agrees_with_a_plain_loop_of_their_definition() -> None:
    D = np.random.default_rng(5).random((24, 40))
    res = matching.match(D, authors(dtype="float64"))
    index, conf = _ref_authors(D, 10, 30)
    np.testing.assert_array_equal(res.index, index)
    np.testing.assert_allclose(res.confidence, conf, rtol=1e-9)


def test_openseqslam_preset_is_the_ratio_with_a_centred_trajectory() -> None:
    seq = matcher_presets.get("openseqslam").config.sequence
    assert (seq.score, seq.ratio_window, seq.enhance_window, seq.shift) == ("ratio", 10, 10, True)
    assert (seq.trajectory, seq.offset_rounding, seq.edge_queries) == ("centred", "floor_start", "skip")
    assert seq.velocities().tolist() == [0.8, 0.9, 1.0, 1.1, 1.2]
    res = matching.match(np.random.default_rng(2).random((30, 40)), seq)
    found = res.index >= 0
    assert ((res.score[found] >= 0) & (res.score[found] <= 1)).all()
    assert not found[:5].any() and not found[-5:].any() and found[5:-5].all()


# --------------------------------------------------------------------------- evaluation level


class Rows(Method):
    """Each view is its own descriptor (a test method)."""

    name = "rows_test"
    version = "1"
    input_kind = "topview"

    def describe(self, maps):
        return np.asarray(maps, dtype=np.float32).reshape(len(maps), -1)


def test_max_frames_and_trim_queries() -> None:
    n = 40
    rng = np.random.default_rng(4)
    views = rng.random((n, 4, 4)).astype(np.float32)
    pos = np.stack([np.arange(n) * 20.0, np.zeros(n)], 1)
    times = np.arange(n) * 0.4
    truth = GroundTruth(pos, pos, times, times, 10.0, 10.0)
    full = evaluate_method(Rows(), views, views, truth)
    assert full.metrics["sequence"].n_queries == n
    cfg = EvaluationConfig(MatcherConfig(ds=4), max_frames=30, trim_queries=6)
    part = evaluate_method(Rows(), views, views, truth, config=cfg)
    assert len(part.matches["sequence"].index) == 30  # every kept query is matched ...
    assert part.metrics["sequence"].n_queries == part.metrics["single_frame"].n_queries == 18
    assert part.n_described == 60
    with pytest.raises(ConfigError, match="trim_queries=20 and 0 context queries leave none of the 40"):
        evaluate_method(Rows(), views, views, truth, config=EvaluationConfig(trim_queries=20))
    with pytest.raises(ConfigError, match="max_frames"):
        EvaluationConfig(max_frames=0)


def test_single_frame_keeps_its_meaning_under_the_authors_score() -> None:
    cfg = matcher_presets.get("authors").config
    single = cfg.single_frame
    assert (single.score, single.shift, single.capped_match, single.preset) == ("min", True, None, "authors")
    assert matcher_presets.get("openseqslam").config.single_frame.score == "ratio"


# --------------------------------------------------------------------------- names and labels


def test_unknown_preset_says_did_you_mean_and_lists_them() -> None:
    with pytest.raises(ConfigError) as err:
        matcher_presets.configure("author")
    message = str(err.value)
    assert "did you mean 'authors'?" in message
    assert "paper, paper-r10, authors, authors-sad, authors-2018, openseqslam" in message
    assert "\n" not in message
    with pytest.raises(ConfigError, match=r"--matcher: unknown setting\(s\) \['speed'\]; valid: \["):
        matcher_presets.configure("paper", {"speed": 2})
    with pytest.raises(ConfigError, match="unknown setting"):
        matcher_presets.configure("paper", {"preset": "authors"})  # the name is --matcher-preset's


def test_refined_preset_is_recorded_whole_and_labelled() -> None:
    cfg = matcher_presets.configure("authors", {"enhance_window": 0, "trim_queries": 2})
    recorded = cfg.to_dict()
    assert recorded["sequence"]["preset"] == "authors" and recorded["sequence"]["enhance_window"] == 0
    assert recorded["sequence"]["score"] == "inverse" and recorded["evaluation"]["trim_queries"] == 2
    assert matcher_presets.label(recorded) == "authors+enhance_window=0,trim_queries=2"
    assert matcher_presets.label(matcher_presets.get("openseqslam").config) == "openseqslam"
    assert EvaluationConfig.from_dict(json.loads(json.dumps(recorded))) == cfg


def test_cli_list_matchers(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["list", "matchers"]) == 0
    out = capsys.readouterr().out
    for preset in matcher_presets.PRESETS.values():
        assert preset.name in out and preset.description in out
    for name in matcher_presets.SETTINGS:
        assert f"\n{name} " in out
    assert "inverse *" in out and "floor_start *" in out
    assert main(["list", "matchers", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) == {"paper", "paper-r10", "authors", "authors-sad", "authors-2018", "openseqslam"}
    assert data["authors"]["settings"]["capped_match"] == 1
    assert set(data["paper"]["settings"]) == {*matcher_presets.SETTINGS, "preset"}
    for preset in data.values():  # every value cites where it comes from
        assert set(preset["citations"]) == set(matcher_presets.SETTINGS)
        assert all(preset["citations"].values())
    assert data["authors"]["citations"]["distance"].startswith("src/util/utils.py:76@25be0fd")
    assert data["authors"]["citations"]["enhance_window"] == (
        "src/plot/SLFL/plotDraw_slfl.py:63@25be0fd (enhanceContrast(D, 30))")


# --------------------------------------------------------------------------- on the command line

TINY = "Test/TinyPreset-T1R1-v0"


@pytest.fixture
def tiny_task(kitti_root: Path, safl_home: Path) -> Iterator[str]:
    tasks.register(TINY, source="kitti", sequence="00", condition="T1R1", step=1,
                   map_config=MapConfig(size=32))
    yield TINY
    tasks.unregister(TINY)


def test_cli_preset_refined_by_matcher_records_both(tiny_task, kitti_root, tmp_path, capsys):
    base = ["run", "--method", "sad", "--task", tiny_task, "--kitti-root", str(kitti_root),
            "--results", str(tmp_path), "--quiet"]
    assert main([*base, "--matcher-preset", "authors", "--matcher", "enhance_window=0",
                 "--matcher", "ds=4", "--matcher", "trim_queries=2"]) == 0
    path = next(tmp_path.rglob("seed-0.json"))
    record = json.loads(path.read_text())
    seq = record["matcher"]["sequence"]
    assert (seq["preset"], seq["enhance_window"], seq["ds"]) == ("authors", 0, 4)
    assert (seq["score"], seq["shift"], seq["capped_match"]) == ("inverse", False, 1)
    assert record["matcher"]["evaluation"] == {"max_frames": 300, "trim_queries": 2,
                                               "distance": "euclidean", "truth_at": "frame"}
    assert matcher_presets.label(record["matcher"]) == "authors+ds=4,enhance_window=0,trim_queries=2"
    assert record["results"]["sequence"]["metrics"]["n_queries"] == 12 - 4
    # --score refines a preset only when given: openseqslam keeps its ratio
    capsys.readouterr()
    assert main([*base, "--matcher-preset", "openseqslam", "--force"]) == 0
    assert json.loads(path.read_text())["matcher"]["sequence"]["score"] == "ratio"
    assert main([*base, "--matcher-preset", "openseqslam", "--score", "min", "--force"]) == 0
    assert matcher_presets.label(json.loads(path.read_text())["matcher"]) == "openseqslam+score=min"
    capsys.readouterr()
    assert main([*base, "--matcher-preset", "authorz"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "did you mean 'authors'?" in err[0] and err[0].startswith("safl-bench: error:")


def test_records_made_as_authors_before_the_rename_read_as_authors_2018() -> None:
    """A record made under the old name (no ``distance`` setting) holds what authors-2018 holds
    now; one made under the new name is the paper-era preset."""
    later = matcher_presets.get("authors-2018").config.to_dict()
    old = json.loads(json.dumps(later).replace('"authors-2018"', '"authors"'))
    del old["evaluation"]["distance"]
    assert matcher_presets.label(old) == "authors-2018" and same_settings(old, later)
    refined = json.loads(json.dumps(old))
    refined["sequence"]["enhance_window"] = 30
    assert matcher_presets.label(refined) == "authors-2018+enhance_window=30"
    new = matcher_presets.get("authors").config.to_dict()
    assert matcher_presets.label(new) == "authors" and not same_settings(old, new)


def test_euclidean_distance_is_the_plain_l2_norm() -> None:
    rng = np.random.default_rng(8)
    views = rng.random((12, 3, 3)).astype(np.float32)
    flat = views.reshape(12, -1).astype(np.float64)
    want = np.linalg.norm(flat[:, None, :] - flat[None, :, :], axis=2)
    D, _, _ = difference_matrix(Rows(), views, views, "euclidean")
    np.testing.assert_allclose(D, want, rtol=1e-4, atol=1e-5)
    D2, _, _ = difference_matrix(Rows(), views, views)
    np.testing.assert_allclose(D2, want ** 2, rtol=1e-4, atol=1e-5)
    with pytest.raises(ConfigError, match="distance must be one of"):
        EvaluationConfig(distance="cosine")


def test_truth_at_is_an_evaluation_setting_that_old_records_read_as_frame() -> None:
    """`--matcher truth_at=viewpoint` is recorded and labelled; a record made before the setting
    existed was scored against the frames' poses, and reads so; a wrong value is one line."""
    want = matcher_presets.configure("authors", {"truth_at": "viewpoint"})
    assert want.truth_at == "viewpoint" and want.to_dict()["evaluation"]["truth_at"] == "viewpoint"
    assert matcher_presets.label(want) == "authors+truth_at=viewpoint"
    before = matcher_presets.configure("authors").to_dict()
    del before["evaluation"]["truth_at"]
    assert same_settings(before, matcher_presets.configure("authors").to_dict())
    assert not same_settings(before, want.to_dict())
    with pytest.raises(ConfigError, match="truth_at must be one of"):
        matcher_presets.configure("authors", {"truth_at": "pose"})
    assert all("truth_at" in p.citations for p in matcher_presets.PRESETS.values())
