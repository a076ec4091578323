"""Exact values of `safl_bench.matching` on small hand-made matrices: the velocity grid and the
trajectory offsets, a planted trajectory small enough to check by hand, the three scores, the
shift, db_limit, and every setting check."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from safl_bench import matching
from safl_bench.errors import ConfigError, DataError
from safl_bench.matching import MatcherConfig, match, seqslam, single_frame
from safl_bench.matching_loop import ref_enhance

# --------------------------------------------------------------------------- grid and offsets


def test_velocity_grids() -> None:
    assert MatcherConfig(method="single_frame", ds=0).velocities().tolist() == [1.0]
    assert MatcherConfig(ds=0, v_min=0.5, v_max=2.0).velocities().tolist() == [1.0]
    assert MatcherConfig(v_max=1.0, v_inclusive=False).velocities().tolist() == [0.8, 0.9]
    assert MatcherConfig(v_max=1.0).velocities().tolist() == [0.8, 0.9, 1.0]
    # the grid stops at the last step that fits: 0.8 + 0.3 k <= 1.2
    assert MatcherConfig(v_step=0.3, v_max=1.2).velocities().tolist() == [0.8, 1.1]
    assert MatcherConfig(v_step=0.3, v_max=1.25).velocities().tolist() == [0.8, 1.1]  # 1.5 steps
    assert MatcherConfig(v_step=0.3, v_max=1.2, v_inclusive=False).velocities().tolist() == [
        0.8, 1.1]
    assert MatcherConfig(v_min=-0.2, v_max=0.2, v_step=0.2).velocities().tolist() == [
        -0.2, 0.0, 0.2]


def test_velocity_grids_are_computed_to_9_decimals() -> None:
    # a step 1.3e-11 off 0.1 (a value read back from a file, say) is the step 0.1: the count
    # of steps and the velocities are rounded to 9 decimals
    assert MatcherConfig(v_step=0.1000000000133).velocities().tolist() == [0.8, 0.9, 1.0, 1.1]
    assert MatcherConfig(v_step=0.1000000004).velocities().tolist() == [0.8, 0.9, 1.000000001]
    # v_max within 1e-9 of a grid velocity is that velocity: excluded when not inclusive
    assert MatcherConfig(v_max=1.1000000004, v_inclusive=False).velocities().tolist() == [
        0.8, 0.9, 1.0]


def test_trajectory_query_offsets() -> None:
    assert MatcherConfig(ds=5).u_range() == (-5, 0)
    assert MatcherConfig(ds=5, trajectory="centred").u_range() == (-3, 2)
    assert MatcherConfig(ds=4, trajectory="centred").u_range() == (-2, 2)
    assert MatcherConfig(method="single_frame", ds=0).u_range() == (0, 0)


def test_offsets_round_half_up_about_the_query() -> None:
    cfg = MatcherConfig(ds=2, v_min=0.5, v_max=1.5, v_step=0.5)
    offs = cfg.offsets()
    # u = -2, -1, 0; V u = (-1, -.5, 0), (-2, -1, 0), (-3, -1.5, 0); half up: -.5 -> 0, -1.5 -> -1
    assert offs.tolist() == [[-1, 0, 0], [-2, -1, 0], [-3, -1, 0]]
    assert offs.dtype == np.int64
    centred = MatcherConfig(ds=2, v_min=1.5, v_max=1.5, trajectory="centred").offsets()
    assert centred.tolist() == [[-1, 0, 2]]  # u = -1, 0, 1: -1.5 -> -1, 1.5 -> 2
    # 0.7 * 5 is 3.4999999999999996 in floats: rounded to 9 digits first, it is 3.5 -> 4
    assert MatcherConfig(ds=5, v_min=0.7, v_max=0.7, trajectory="centred",
                         ).offsets().tolist() == [[-2, -1, -1, 0, 1, 1]]
    assert MatcherConfig(ds=10, v_min=0.7, v_max=0.7).offsets()[0, 5] == -3  # -3.5 -> -3


def test_offsets_floor_from_the_first_query() -> None:
    cfg = MatcherConfig(ds=2, v_min=0.5, v_max=1.5, v_step=0.5, offset_rounding="floor_start")
    # j0 + floor(V k), k = 0, 1, 2, relative to the reported frame j0 + 2
    assert cfg.offsets().tolist() == [[-2, -2, -1], [-2, -1, 0], [-2, -1, 1]]
    assert cfg.offsets().dtype == np.int64
    centred = MatcherConfig(ds=4, v_min=1.5, v_max=1.5, trajectory="centred",
                            offset_rounding="floor_start").offsets()
    assert centred.tolist() == [[-2, -1, 1, 2, 4]]  # floor(0, 1.5, 3, 4.5, 6) - 2


# --------------------------------------------------------------------------- a trajectory by hand


def planted() -> np.ndarray:
    """3 queries x 6 frames of ones; zeros at (0, 0), (1, 2), (2, 4): a trajectory at V = 2."""
    D = np.ones((3, 6))
    D[0, 0] = D[1, 2] = D[2, 4] = 0.0
    return D


def test_a_trajectory_at_velocity_two_by_hand() -> None:
    cfg = MatcherConfig(ds=2, v_min=1.0, v_max=2.0, v_step=1.0, enhance_window=0,
                        dtype="float64")
    res = match(planted() + 3.0, cfg, keep_S=True)  # +3: the shift takes it off again
    # query 0 sees one row: frame 0 at either velocity, the lower wins; query 1: rows 0-1,
    # frames (0, 2) at V = 2; query 2: (0, 2, 4) at V = 2
    assert res.index.tolist() == [0, 2, 4]
    assert res.velocity.tolist() == [1.0, 2.0, 2.0]
    assert res.n_terms.tolist() == [1, 2, 3] and res.complete.tolist() == [False, False, True]
    assert res.score.tolist() == [0.0, 0.0, 0.0] and res.best_s.tolist() == [0.0, 0.0, 0.0]
    assert res.S is not None and res.S.dtype == np.float64
    S32 = match(planted(), dataclass_replace(cfg, dtype="float32"), keep_S=True).S
    assert S32 is not None and S32.dtype == np.float32  # in the matcher's precision
    # S(2, j): at V = 1 the trajectory (j-2, j-1, j) needs j >= 2; at V = 2, j >= 4
    np.testing.assert_allclose(res.S[2], [np.inf, np.inf, 2 / 3, 2 / 3, 0.0, 1.0])
    np.testing.assert_allclose(res.S[1], [np.inf, 0.5, 0.0, 1.0, 1.0, 1.0])
    skip = match(planted(), dataclass_replace(cfg, edge_queries="skip"))
    assert skip.index.tolist() == [-1, -1, 4] and skip.score[:2].tolist() == [np.inf, np.inf]
    assert np.isnan(skip.velocity[:2]).all() and skip.velocity[2] == 2.0
    # the last candidates only: query 2 may not report 4
    lim = match(planted(), cfg, db_limit=np.array([6, 6, 4]))
    assert lim.index.tolist() == [0, 2, 2] and lim.velocity[2] == 1.0
    assert lim.score[2] == pytest.approx(2 / 3)  # (D[0,0] + D[1,1] + D[2,2]) / 3


def dataclass_replace(cfg: MatcherConfig, **kw: object) -> MatcherConfig:
    return MatcherConfig(**{**cfg.to_dict(), **kw})


def test_clip_reads_the_edge_columns() -> None:
    cfg = MatcherConfig(ds=2, v_min=2.0, v_max=2.0, enhance_window=0, dtype="float64",
                        out_of_range="clip")
    D = np.array([[0.0, 9, 9, 9], [9, 9, 9, 9], [9, 9, 0, 9]])
    res = match(D, cfg, keep_S=True)
    # query 2 at frame j reads columns j - 4, j - 2, j: frame 2 (-2 -> 0, 0, 2): 0 + 9 + 0;
    # frame 1 (0, 0, 1): 0 + 9 + 9; frame 3 (0, 1, 3): 0 + 9 + 9
    assert res.S is not None and res.S[2].tolist() == [6.0, 6.0, 3.0, 6.0]
    assert res.index.tolist() == [0, 0, 2]
    excl = match(D, dataclass_replace(cfg, out_of_range="exclude"), keep_S=True)
    # no trajectory of query 2 fits: it needs j >= 4
    assert excl.S is not None and np.isinf(excl.S[2]).all() and excl.index[2] == -1
    assert excl.S[1].tolist() == [np.inf, np.inf, 4.5, 9.0] and excl.index[1] == 2


# --------------------------------------------------------------------------- scores


def test_ratio_score_by_hand() -> None:
    D = np.array([[2.0, 3, 4, 6], [1, 5, 5, 3]])
    # shifted by the minimum 1: rows (1, 2, 3, 5) and (0, 4, 4, 2); ratio_window 2: |j - j*| > 1
    res = single_frame(D, score="ratio", ratio_window=2, dtype="float64")
    assert res.index.tolist() == [0, 0]
    np.testing.assert_allclose(res.score, [1 / 3, 0.0])
    np.testing.assert_allclose(res.best_s, [1.0, 0.0])
    assert single_frame(D, score="ratio", ratio_window=3).score.tolist() == pytest.approx(
        [1 / 3, 0.0])  # 3 // 2 = 1 as well
    # no frame beyond the window: no evidence, 1.0
    assert single_frame(D, score="ratio", ratio_window=10).score.tolist() == [1.0, 1.0]
    # the other frame is as good: S of it is 0, no evidence either
    tie = single_frame(np.array([[1.0, 5, 1]]), score="ratio", ratio_window=0)
    assert tie.index.tolist() == [0] and tie.score.tolist() == [1.0]
    none = single_frame(D, score="ratio", db_limit=np.array([0, 4]), ratio_window=2)
    assert none.index.tolist() == [-1, 0] and none.score[0] == np.inf


def test_inverse_score_by_hand() -> None:
    D = np.array([[0.5, 3.0], [2.0, 4.0], [-1.0, 0.2]])
    raw = single_frame(D, score="inverse", shift=False, dtype="float64")
    # S = 0.5, 2, -1 (one term each): 1/S = 2 (capped to 1), 0.5, -1 (a negative S ranks last)
    assert raw.index.tolist() == [0, 0, 0]
    np.testing.assert_allclose(raw.score, [-1.0, -0.5, 1.0])
    np.testing.assert_allclose(raw.best_s, [0.5, 2.0, -1.0])
    capped = single_frame(D, score="inverse", shift=False, capped_match=1)
    assert capped.index.tolist() == [1, 0, 0]  # only the capped query answers frame 1
    with pytest.raises(ConfigError, match=r"^capped_match=2 is not a database frame "
                                          r"\(the database has 2\)$"):
        single_frame(D, score="inverse", shift=False, capped_match=2)
    # shifted by -1: S = 1.5, 3, 0; S = 0 is capped too (1 / 0)
    shifted = single_frame(D, score="inverse", dtype="float64", capped_match=1)
    np.testing.assert_allclose(shifted.score, [-1 / 1.5, -1 / 3, -1.0])
    assert shifted.index.tolist() == [0, 0, 1]
    # a capped query that is not found is not moved: nothing is capped when nothing is found
    lim = single_frame(D, score="inverse", shift=False, capped_match=1, db_limit=np.array([0, 2, 2]))
    assert lim.index.tolist() == [-1, 0, 0] and lim.score[0] == np.inf


def test_inverse_score_reads_the_trajectory_sum() -> None:
    best_s = np.array([0.5, 0.4, -1.0, np.inf, 0.0, 0.5, -0.0])
    n_terms = np.array([3, 2, 2, 3, 1, 2, 1])
    found = np.array([True, True, True, False, True, True, True])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # 1 / 0 is the cap, not a warning
        score, capped = matching._inverse_score(best_s, n_terms, found)
    # sums 1.5, 0.8, -2, -, 0, 1, -0: 1/sum = .667, 1.25 (capped), -.5, -, inf (capped), 1 (not
    # capped: capped means 0 <= S_sum < 1), -inf (capped: -0 is 0)
    np.testing.assert_allclose(score, [-1 / 1.5, -1.0, 0.5, np.inf, -1.0, -1.0, -1.0])
    assert capped.tolist() == [False, True, False, False, True, False, True]


def test_a_sum_of_exactly_one_is_not_capped() -> None:
    D = np.array([[1.0, 3.0], [0.5, 2.0]])
    res = single_frame(D, score="inverse", shift=False, capped_match=1, dtype="float64")
    assert res.score.tolist() == [-1.0, -1.0]  # 1/1 and min(1/0.5, 1)
    assert res.index.tolist() == [0, 1]  # only the capped query reports frame 1


def test_min_score_is_the_shifted_mean() -> None:
    res = seqslam(planted() * 2 + 1, ds=2, v_min=1.0, v_max=2.0, v_step=1.0, enhance_window=0,
                  dtype="float64", db_limit=np.array([6, 6, 4]))
    assert res.score[2] == pytest.approx(4 / 3)  # (2 + 2 + 0) / 3 after the shift by 1
    unshifted = seqslam(planted() * 2 + 1, ds=2, v_min=1.0, v_max=2.0, v_step=1.0,
                        enhance_window=0, dtype="float64", shift=False)
    assert unshifted.score.tolist() == [1.0, 1.0, 1.0] and unshifted.best_s[2] == 1.0


# --------------------------------------------------------------------------- enhancement


def test_enhanced_matrix_is_what_the_search_reads() -> None:
    rng = np.random.default_rng(5)
    D = rng.random((4, 9)).astype(np.float32)
    keep = D.copy()
    cfg = MatcherConfig(enhance_window=4)
    E = matching.enhanced_matrix(D, cfg)
    ref = ref_enhance(D.astype(np.float64), 4, "centred")
    np.testing.assert_allclose(E, ref - ref.min(), atol=1e-5)
    assert E.dtype == np.float32 and E.min() == 0.0
    np.testing.assert_array_equal(D, keep)  # a float32 input is never enhanced in place
    match(D, cfg)
    np.testing.assert_array_equal(D, keep)
    noshift = matching.enhanced_matrix(D, MatcherConfig(enhance_window=4, shift=False))
    np.testing.assert_allclose(noshift, ref, atol=1e-5)
    raw = matching.enhanced_matrix(D, MatcherConfig(enhance_window=0))
    assert raw is not D and not np.may_share_memory(raw, D)
    np.testing.assert_allclose(raw, D - D.min())
    np.testing.assert_array_equal(D, keep)
    raw64 = matching.enhanced_matrix(D.astype(np.float64), MatcherConfig(enhance_window=0,
                                                                          shift=False))
    assert raw64.dtype == np.float32
    np.testing.assert_array_equal(raw64, D)
    one = matching.enhanced_matrix(D, MatcherConfig(enhance_window=1, enhance_mode="causal",
                                                    shift=False))
    np.testing.assert_allclose(one, ref_enhance(D.astype(np.float64), 1, "causal"), atol=1e-5)
    causal = matching.enhanced_matrix(D, MatcherConfig(enhance_window=3, enhance_mode="causal",
                                                       shift=False))
    np.testing.assert_allclose(causal, ref_enhance(D.astype(np.float64), 3, "causal"), atol=1e-5)


def test_enhance_by_hand() -> None:
    row = np.array([[0.0, 1.0, 3.0]])
    # causal window 2: j = 0 alone -> 0; j = 1: (1 - .5) / .7071; j = 2: (3 - 4/3) / 1.5275
    np.testing.assert_allclose(matching.enhance(row, 2, "causal"),
                               [[0.0, 0.5 / np.sqrt(0.5), (5 / 3) / np.sqrt(7 / 3)]])
    # centred window 2: [j - 1, j + 1]
    np.testing.assert_allclose(matching.enhance(row, 2), ref_enhance(row, 2, "centred"))
    off = matching.enhance(row, 0)
    assert off is not row and off.tolist() == row.tolist() and off.dtype == np.float64
    out = np.empty((1, 3), np.float32)
    got = matching.enhance(row, 2, "causal", dtype="float32", out=out)
    assert got is out and out[0, 0] == 0.0 and out[0, 1] == pytest.approx(0.5 / np.sqrt(0.5))
    np.testing.assert_allclose(matching.enhance(row, 1, "causal"),
                               [[0.0, 1 / np.sqrt(2), 1 / np.sqrt(2)]])
    with pytest.raises(ConfigError, match=r"^enhance window must be 0 \(off\) or >= 2, got -1$"):
        matching.enhance(row, -1)
    with pytest.raises(ConfigError, match=r"^enhance window must be 0 \(off\) or >= 2, got 1$"):
        matching.enhance(row, 1)
    with pytest.raises(ConfigError, match=r"^enhance mode must be 'centred' or 'causal', got "):
        matching.enhance(row, 2, "future")
    with pytest.raises(ConfigError, match=r"^dtype must be 'float32' or 'float64', got 'float16'"):
        matching.enhance(row, 2, dtype="float16")


def test_enhance_defaults_are_the_papers() -> None:
    D = np.random.default_rng(4).random((3, 25))
    np.testing.assert_allclose(matching.enhance(D), ref_enhance(D, 10, "centred"), atol=1e-7)
    np.testing.assert_allclose(matching.enhance(D, mode="causal"), ref_enhance(D, 10, "causal"),
                               atol=1e-7)
    # float64 unless asked, whatever the input
    assert matching.enhance(D.astype(np.float32), 0).dtype == np.float64
    assert matching.enhance(D.astype(np.float32)).dtype == np.float64
    assert matching.enhance(D, 4, dtype="float32").dtype == np.float32


# --------------------------------------------------------------------------- input checks


def test_difference_matrix_checks() -> None:
    with pytest.raises(DataError, match=r"^difference matrix must be 2-D \(queries x database\)"):
        match(np.ones(3))
    with pytest.raises(DataError, match=r"^difference matrix is empty \(shape \(2, 0\)\)$"):
        match(np.ones((2, 0)))
    with pytest.raises(DataError, match=r"^difference matrix must hold real numbers"):
        match(np.ones((2, 2), dtype=complex))
    with pytest.raises(DataError, match=r"^difference matrix must hold real numbers"):
        match(np.array([[True, False]]))
    with pytest.raises(DataError, match=r"^difference matrix has 2 NaN or infinite entries$"):
        match(np.array([[1.0, np.nan, -np.inf]]))
    ints = match(np.array([[3, 1], [0, 2]]), MatcherConfig(method="single_frame", ds=0,
                                                          enhance_window=0))
    assert ints.index.tolist() == [1, 0] and ints.score.tolist() == [1.0, 0.0]


def test_db_limit_checks() -> None:
    D = np.ones((2, 3))
    for bad in (np.array([1.0, 2.0]), np.array([1, 2, 3]), np.array([[1, 2]])):
        with pytest.raises(DataError, match=r"^db_limit must be an integer array of shape \(2,\)"):
            match(D, db_limit=bad)
    for bad in (np.array([-1, 2]), np.array([1, 4])):
        with pytest.raises(DataError, match=r"^db_limit values must lie in \[0, 3\]$"):
            match(D, db_limit=bad)
    ok = single_frame(np.array([[3.0, 2, 1], [1, 2, 3]]), db_limit=np.array([3, 0], np.int32))
    assert ok.index.tolist() == [2, -1]


@pytest.mark.parametrize(
    ("bad", "says"),
    [(dict(method="loop"), "method must be 'seqslam' or 'single_frame', got 'loop'"),
     (dict(ds=True), "ds must be an integer >= 0, got True"),
     (dict(ds=2.0), "ds must be an integer >= 0, got 2.0"),
     (dict(method="single_frame", ds=1), "single_frame matching has ds = 0, got ds=1"),
     (dict(v_min=np.inf), "v_min must be finite, got inf"),
     (dict(v_step=np.nan), "v_step must be finite, got nan"),
     (dict(v_step=-0.1), "v_step must be > 0, got -0.1"),
     (dict(v_min=1.2, v_max=1.0), r"v_max \(1.0\) must be >= v_min \(1.2\)"),
     (dict(enhance_window=-1), r"enhance_window must be 0 \(off\) or >= 2, got -1"),
     (dict(enhance_mode="forward"), "enhance_mode must be 'centred' or 'causal', got 'forward'"),
     (dict(trajectory="future"), "trajectory must be 'causal' or 'centred', got 'future'"),
     (dict(edge_queries="drop"), "edge_queries must be 'shorten' or 'skip', got 'drop'"),
     (dict(out_of_range="wrap"), "out_of_range must be 'exclude' or 'clip', got 'wrap'"),
     (dict(score="max"), "score must be one of 'min', 'ratio', 'inverse', got 'max'"),
     (dict(ratio_window=-1), "ratio_window must be >= 0, got -1"),
     (dict(dtype="float16"), "dtype must be 'float32' or 'float64', got 'float16'"),
     (dict(shift=1), "shift must be true or false, got 1"),
     (dict(offset_rounding="round"),
      "offset_rounding must be 'half_up' or 'floor_start', got 'round'"),
     (dict(capped_match=True), r"capped_match must be null \(keep the match\) or a frame index"),
     (dict(capped_match=-1), r"capped_match must be null \(keep the match\) or a frame index"),
     (dict(capped_match=1.0), r"capped_match must be null \(keep the match\) or a frame index"),
     (dict(preset=""), "preset must be a preset's name, got ''"),
     (dict(preset=3), "preset must be a preset's name, got 3"),
     (dict(v_min=1.0, v_max=1.0, v_inclusive=False),
      r"the velocity grid is empty \(v_inclusive=False and v_min == v_max\)$")],
)
def test_each_setting_is_checked(bad: dict, says: str) -> None:
    with pytest.raises(ConfigError, match=f"^matcher config: {says}"):
        MatcherConfig(**bad)


def test_settings_at_their_limits_are_accepted() -> None:
    assert MatcherConfig(enhance_window=1, enhance_mode="causal").enhance_window == 1
    assert MatcherConfig(ratio_window=0, ds=0, v_step=1e-3).ratio_window == 0
    assert MatcherConfig(shift=np.bool_(False), capped_match=np.int64(0)).capped_match == 0
    assert MatcherConfig(ds=np.int64(3), v_min=1.1, v_max=1.1).ds == 3
    assert MatcherConfig(method="single_frame", ds=0, score="ratio").score == "ratio"


def test_settings_round_trip_and_unknown_ones() -> None:
    cfg = MatcherConfig(ds=3, score="inverse", capped_match=1, preset="authors")
    d = cfg.to_dict()
    assert d["ds"] == 3 and d["capped_match"] == 1 and len(d) == 19
    assert MatcherConfig.from_dict(d) == cfg
    assert MatcherConfig.from_dict({"ds": 4}) == MatcherConfig(ds=4)  # older records
    with pytest.raises(ConfigError, match=r"^matcher settings: unknown setting\(s\) \['a', 'z'\]"):
        MatcherConfig.from_dict({"z": 1, "a": 2, "ds": 3})
    with pytest.raises(ConfigError, match=r"^matcher settings must be a mapping"):
        MatcherConfig.from_dict([("ds", 3)])  # type: ignore[arg-type]


def test_wrappers_pass_their_settings_and_name_themselves() -> None:
    with pytest.raises(ConfigError, match=r"^seqslam: "):
        seqslam(np.ones((2, 2)), nonsense=1)
    with pytest.raises(ConfigError, match=r"^single_frame: "):
        single_frame(np.ones((2, 2)), nonsense=1)
    D = np.random.default_rng(2).random((5, 7))
    s = single_frame(D, score="ratio", ratio_window=4, enhance_window=2, keep_S=True,
                     db_limit=np.full(5, 6))
    assert (s.config.score, s.config.ratio_window, s.config.enhance_window) == ("ratio", 4, 2)
    assert s.S is not None and np.isinf(s.S[:, 6]).all() and np.all(s.index < 6)
    q = seqslam(D, ds=2, v_min=0.5, v_max=1.5, v_step=0.5, enhance_window=3, keep_S=True,
                db_limit=np.full(5, 6), trajectory="centred")
    assert (q.config.ds, q.config.v_min, q.config.v_max, q.config.v_step) == (2, 0.5, 1.5, 0.5)
    assert (q.config.enhance_window, q.config.trajectory, q.config.method) == (3, "centred",
                                                                                "seqslam")
    assert q.S is not None and np.all(q.index < 6)
    assert single_frame(D).S is None and seqslam(D).S is None
    # the recorded settings of the defaults are the documented ones
    assert single_frame(D).config == MatcherConfig(method="single_frame", ds=0, enhance_window=0)
    assert seqslam(D).config == MatcherConfig()


def test_result_to_dict_by_hand() -> None:
    cfg = MatcherConfig(ds=2, v_min=1.0, v_max=2.0, v_step=1.0, enhance_window=0,
                        edge_queries="skip")
    blob = match(planted(), cfg).to_dict()
    assert json.loads(json.dumps(blob, allow_nan=False)) == {
        "config": cfg.to_dict(), "index": [-1, -1, 4], "score": [None, None, 0.0],
        "best_s": [None, None, 0.0], "velocity": [None, None, 2.0], "n_terms": [1, 2, 3]}
    conf = match(planted(), cfg).confidence
    assert conf.tolist() == [-np.inf, -np.inf, -0.0]
