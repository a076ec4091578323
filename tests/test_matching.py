"""The vectorised matcher against a plain-loop implementation of the same equations."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from safl_bench import distance, matching
from safl_bench.errors import ConfigError, DataError
from safl_bench.matching import MatcherConfig
from safl_bench.matching_loop import ref_enhance, ref_match


def assert_same(res: matching.MatchResult, ref, rtol: float = 1e-9) -> None:
    index, score, velocity, S = ref
    np.testing.assert_array_equal(res.index, index)
    np.testing.assert_allclose(res.score, score, rtol=rtol, atol=rtol)
    np.testing.assert_allclose(res.velocity, velocity, rtol=0, atol=1e-12)
    if res.S is not None:
        np.testing.assert_allclose(res.S, S, rtol=rtol, atol=rtol)


# --------------------------------------------------------------------------- agreement


@pytest.fixture(scope="module")
def rand_D() -> np.ndarray:
    return np.random.default_rng(1).random((30, 42))


def test_enhance_matches_loop(rand_D: np.ndarray) -> None:
    for window, mode in [(10, "centred"), (6, "causal"), (1, "causal"), (3, "centred")]:
        got = matching.enhance(rand_D, window, mode)
        # prefix sums: a few 1e-9 off on 2-frame windows
        np.testing.assert_allclose(got, ref_enhance(rand_D, window, mode), rtol=1e-7, atol=1e-7)


def test_enhance_constant_row_is_zero() -> None:
    D = np.ones((3, 20))
    D[1] = np.arange(20.0)
    out = matching.enhance(D, 10)
    assert np.all(out[0] == 0) and np.all(out[2] == 0)
    np.testing.assert_allclose(out[1], ref_enhance(D, 10, "centred")[1])


def test_seqslam_defaults_match_loop(rand_D: np.ndarray) -> None:
    res = matching.seqslam(rand_D, dtype="float64", keep_S=True)
    assert_same(res, ref_match(rand_D, res.config))
    assert res.config == MatcherConfig(dtype="float64")


@pytest.mark.parametrize(
    "options",
    [
        dict(score="ratio"),
        dict(trajectory="centred", score="ratio", ratio_window=6),
        dict(out_of_range="clip"),
        dict(edge_queries="skip", enhance_mode="causal"),
        dict(enhance_window=0, ds=4, v_min=0.5, v_max=1.5, v_step=0.25),
        dict(ds=7, v_min=-1.2, v_max=-0.8, v_step=0.2, trajectory="centred", out_of_range="clip"),
        dict(ds=3, v_min=1.0, v_max=1.0, enhance_window=4),
    ],
)
def test_seqslam_options_match_loop(rand_D: np.ndarray, options: dict) -> None:
    res = matching.seqslam(rand_D, dtype="float64", keep_S=True, **options)
    assert_same(res, ref_match(rand_D, res.config))


def test_seqslam_float32_agrees_with_loop(rand_D: np.ndarray) -> None:
    res = matching.seqslam(rand_D.astype(np.float32), keep_S=True)
    assert res.config.dtype == "float32"
    assert_same(res, ref_match(rand_D.astype(np.float32).astype(np.float64), res.config),
                rtol=2e-5)


def test_db_limit_matches_loop(rand_D: np.ndarray) -> None:
    limit = np.clip(np.arange(30) + 5, 0, 42)
    limit[3] = 0
    res = matching.seqslam(rand_D, dtype="float64", db_limit=limit, score="ratio")
    ref = ref_match(rand_D, res.config, db_limit=limit)
    assert_same(res, ref)
    assert res.index[3] == -1 and res.score[3] == np.inf
    assert np.all(res.index < limit)


def test_edge_queries_shorten_and_skip(rand_D: np.ndarray) -> None:
    res = matching.seqslam(rand_D)
    np.testing.assert_array_equal(res.n_terms, np.minimum(np.arange(30), 10) + 1)
    np.testing.assert_array_equal(res.complete, np.arange(30) >= 10)
    assert np.all(res.index >= 0)
    skip = matching.seqslam(rand_D, edge_queries="skip")
    assert np.all(skip.index[:10] == -1) and np.all(np.isinf(skip.score[:10]))
    np.testing.assert_array_equal(skip.index[10:], res.index[10:])
    centred = matching.seqslam(rand_D, trajectory="centred")
    assert centred.n_terms[0] == 6 and centred.n_terms[20] == 11 and centred.n_terms[29] == 6


def test_planted_trajectory_single_query() -> None:
    rng = np.random.default_rng(7)
    D = 0.5 + 0.5 * rng.random((60, 80))
    T0, j0 = 45, 50
    offs = MatcherConfig().offsets()[1]  # velocity 0.9
    for k, u in enumerate(range(-10, 1)):
        D[T0 + u, j0 + offs[k]] = 0.0
    res = matching.seqslam(D)
    assert res.index[T0] == j0
    assert res.velocity[T0] == pytest.approx(0.9)


def test_planted_route_at_velocity_09_is_found() -> None:
    """A database route at 0.9 frames per query, hidden by per-frame distractors."""
    rng = np.random.default_rng(3)
    nq, ndb = 150, 200
    D = 0.6 + 0.4 * rng.random((nq, ndb))
    route = np.floor(15 + 0.9 * np.arange(nq) + 0.5).astype(int)
    D[np.arange(nq), route] = 0.3
    distract = rng.integers(0, ndb, nq)  # single-frame decoys, lower than the route
    D[np.arange(nq), distract] = 0.2
    decoy_wins = route != distract
    single = matching.single_frame(D)
    assert np.mean(single.index[decoy_wins] == route[decoy_wins]) < 0.1
    res = matching.seqslam(D)
    full = res.complete
    # the route is rounded to frames, a trajectory's points are rounded from its end: +-1
    assert np.all(np.abs(res.index[full] - route[full]) <= 1)
    assert np.median(res.velocity[full]) == pytest.approx(0.9)


# --------------------------------------------------------------------------- single frame


def test_single_frame_is_row_argmin(rand_D: np.ndarray) -> None:
    res = matching.single_frame(rand_D, dtype="float64")
    np.testing.assert_array_equal(res.index, np.argmin(rand_D, axis=1))
    np.testing.assert_allclose(res.score, rand_D.min(axis=1) - rand_D.min())
    assert res.config.method == "single_frame" and res.config.ds == 0
    assert np.all(res.complete)
    ratio = matching.single_frame(rand_D, score="ratio", dtype="float64")
    assert_same(ratio, ref_match(rand_D, ratio.config))
    limit = np.full(30, 7)
    lim = matching.single_frame(rand_D, db_limit=limit, dtype="float64")
    np.testing.assert_array_equal(lim.index, np.argmin(rand_D[:, :7], axis=1))


# --------------------------------------------------------------------------- config, errors


def test_velocity_grid_is_float_safe() -> None:
    np.testing.assert_array_equal(MatcherConfig().velocities(), [0.8, 0.9, 1.0, 1.1])
    authors = MatcherConfig(v_max=1.2, v_inclusive=False).velocities()
    np.testing.assert_array_equal(authors, [0.8, 0.9, 1.0, 1.1])
    fine = MatcherConfig(v_step=0.05).velocities()
    np.testing.assert_array_equal(fine, [0.8, 0.85, 0.9, 0.95, 1.0, 1.05, 1.1])
    assert MatcherConfig(v_min=0.7, v_max=0.7).velocities().tolist() == [0.7]
    offs = MatcherConfig().offsets()
    assert offs.shape == (4, 11) and offs[:, -1].tolist() == [0, 0, 0, 0]
    assert offs[:, 0].tolist() == [-8, -9, -10, -11]


@pytest.mark.parametrize(
    "bad",
    [dict(ds=-1), dict(v_step=0), dict(v_min=1.2, v_max=1.0), dict(enhance_window=1),
     dict(score="max"), dict(trajectory="future"), dict(out_of_range="wrap"),
     dict(dtype="float16"), dict(v_min=1.0, v_max=1.0, v_inclusive=False),
     dict(v_max=float("nan")), dict(no_such_option=1)],
)
def test_bad_config_is_config_error(bad: dict) -> None:
    with pytest.raises(ConfigError):
        matching.seqslam(np.ones((3, 3)), **bad)


@pytest.mark.parametrize(
    "D",
    [np.ones(5), np.ones((0, 4)), np.array([[1.0, np.nan]]), np.array([[1.0, np.inf]]),
     np.array([["a", "b"]])],
)
def test_bad_matrix_is_data_error(D: np.ndarray) -> None:
    with pytest.raises(DataError):
        matching.seqslam(D)


def test_bad_db_limit_is_data_error(rand_D: np.ndarray) -> None:
    with pytest.raises(DataError):
        matching.seqslam(rand_D, db_limit=np.full(30, 43))
    with pytest.raises(DataError):
        matching.seqslam(rand_D, db_limit=np.full(3, 5))


def test_result_to_dict_is_json(rand_D: np.ndarray) -> None:
    res = matching.seqslam(rand_D, edge_queries="skip")
    blob = json.loads(json.dumps(res.to_dict()))
    assert blob["config"]["ds"] == 10 and blob["score"][0] is None
    assert len(blob["index"]) == 30
    conf = res.confidence
    assert np.all(conf[10:] == -res.score[10:]) and np.all(conf[:10] == -np.inf)


def test_input_not_modified(rand_D: np.ndarray) -> None:
    D = rand_D.copy()
    matching.seqslam(D, dtype="float64")
    np.testing.assert_array_equal(D, rand_D)


def test_tiny_matrices() -> None:
    res = matching.seqslam(np.array([[3.0]]))
    assert res.index.tolist() == [0] and res.score.tolist() == [0.0]
    res = matching.seqslam(np.array([[1.0, 2.0], [2.0, 1.0]]), out_of_range="exclude")
    assert res.index.tolist() == [0, 1]


# --------------------------------------------------------------------------- distance


@pytest.mark.parametrize("dtype,rtol", [("float64", 1e-9), ("float32", 1e-3)])
def test_sqeuclidean_matches_cdist(dtype: str, rtol: float) -> None:
    rng = np.random.default_rng(0)
    q = rng.standard_normal((33, 16)) + 5
    b = rng.standard_normal((47, 16)) + 5
    got = distance.sqeuclidean(q, b, dtype=dtype, chunk_rows=10)
    assert got.dtype == np.dtype(dtype) and got.shape == (33, 47)
    np.testing.assert_allclose(got, cdist(q, b, "sqeuclidean"), rtol=rtol, atol=rtol)
    assert distance.sqeuclidean(q, q, dtype=dtype).diagonal().max() < 1e-3


def test_sqeuclidean_errors() -> None:
    with pytest.raises(DataError):
        distance.sqeuclidean(np.ones((3, 4)), np.ones((3, 5)))
    with pytest.raises(DataError):
        distance.sqeuclidean(np.ones(3), np.ones((3, 3)))
    with pytest.raises(DataError):
        distance.sqeuclidean(np.full((2, 2), np.nan), np.ones((3, 2)))
    with pytest.raises(DataError):
        distance.sqeuclidean(np.ones((2, 2)), np.ones((3, 2)), dtype="int8")
