"""The matcher in query blocks (`safl_bench.matching.blocks`) gives the whole matrix's answer bit
for bit, for every preset and edge setting, and bounds the rows it holds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from safl_bench.errors import ConfigError, DataError
from safl_bench.matching import blocks, presets
from safl_bench.matching.matcher import MatcherConfig, MatchResult, match
from safl_bench.methods.distance import sqeuclidean

FIELDS = ("index", "score", "best_s", "velocity", "n_terms", "complete")


def same(a: MatchResult, b: MatchResult) -> None:
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype, name
        np.testing.assert_array_equal(x, y, err_msg=name, strict=True)
    assert a.enhance_window == b.enhance_window and a.config == b.config


def route_matrix(nq: int, ndb: int, seed: int = 0) -> np.ndarray:
    """Descriptors whose queries revisit a stretch of the database, as a difference matrix."""
    rng = np.random.default_rng(seed)
    db = np.cumsum(rng.standard_normal((ndb, 16)), axis=0).astype(np.float32)
    q = db[(np.arange(nq) * 7 // 8 + 5) % ndb] + 0.3 * rng.standard_normal((nq, 16)).astype(np.float32)
    return sqeuclidean(q, db)


CONFIGS = [presets.get(n).config.sequence for n in presets.names()] + [
    MatcherConfig(trajectory="centred", edge_queries="skip", score="ratio"),
    MatcherConfig(out_of_range="clip", enhance_mode="causal", score="inverse", shift=False),
    MatcherConfig(offset_rounding="floor_start", trajectory="centred", dtype="float64"),
    MatcherConfig(method="single_frame", ds=0, enhance_window=0),
]


@pytest.mark.parametrize("cfg", CONFIGS, ids=lambda c: f"{c.preset}-{c.trajectory}-{c.score}")
@pytest.mark.parametrize("block", [1, 3, 11, 64])
def test_blocks_equal_the_whole_matrix(cfg: MatcherConfig, block: int) -> None:
    D = route_matrix(90, 70)
    window = 16 if cfg.needs_window else None
    limit = np.clip(np.arange(90) - 5, 0, 70).astype(np.int64)
    for db_limit in (None, limit):
        whole = match(D, cfg, db_limit=db_limit, enhance_window=window)
        (got,), _ = blocks.match_rows(lambda a, b: D[a:b], 90, 70, [cfg], db_limit=db_limit,
                                      windows=[window], block=block)
        same(got, whole)


@pytest.mark.parametrize("parts", [1, 2, 5])
@pytest.mark.parametrize("block", [1, 7, 30])
def test_spans_searched_apart_and_combined_equal_the_whole_matrix(block: int, parts: int) -> None:
    """What `--workers`/`--ray` spread over the workers: each span of whole blocks, searched on
    its own (computing its own blocks, reading the rows its trajectories reach beyond it), in
    any order, joins into the whole matrix's answer bit for bit; every row is visited once."""
    D = route_matrix(90, 70, seed=2)
    cfgs = CONFIGS[:3] + CONFIGS[-4:]
    windows = [16 if c.needs_window else None for c in cfgs]
    limit = np.clip(np.arange(90) - 5, 0, 70).astype(np.int64)
    cut = blocks.spans(90, block, parts)
    assert cut[0][0] == 0 and cut[-1][1] == 90 and len(cut) == min(parts, -(-90 // block))
    assert all(a % block == 0 and b > a for a, b in cut)
    seen: list[int] = []
    found = [blocks.search_span(lambda a, b: D[a:b], 90, 70, cfgs, span, db_limit=limit,
                                windows=windows, block=block,
                                visit=lambda a, rows: seen.extend(range(a, a + len(rows))))
             for span in reversed(cut)]
    got, _ = blocks.combine(cfgs, found, 90, 70, windows=windows)
    for cfg, window, result in zip(cfgs, windows, got, strict=True):
        same(result, match(D, cfg, db_limit=limit, enhance_window=window))
    assert sorted(seen) == list(range(90))
    with pytest.raises(DataError, match="gap or overlap at query 0 of 90"):
        blocks.combine(cfgs, found[:-1], 90, 70, windows=windows)
    with pytest.raises(DataError, match="gap or overlap"):
        blocks.combine(cfgs, [*found, found[0]], 90, 70, windows=windows)
    if block > 1:
        with pytest.raises(ConfigError, match=r"query span \[1, 5\) is not whole blocks"):
            blocks.search_span(lambda a, b: D[a:b], 90, 70, cfgs, (1, 5), block=block,
                               windows=windows)


def test_several_settings_share_the_rows_and_visit_sees_each_once() -> None:
    D = route_matrix(50, 40, seed=1)
    seen: list[tuple[int, int]] = []
    cfgs = [MatcherConfig(), MatcherConfig(method="single_frame", ds=0, enhance_window=0)]
    results, seconds = blocks.match_rows(lambda a, b: D[a:b], 50, 40, cfgs, block=7,
                                         visit=lambda a, rows: seen.append((a, len(rows))))
    for cfg, got in zip(cfgs, results, strict=True):
        same(got, match(D, cfg))
    assert seen == [(a, min(7, 50 - a)) for a in range(0, 50, 7)]
    assert len(seconds) == 2 and all(s >= 0 for s in seconds)


def test_block_rows_follow_the_budget() -> None:
    # 100 000 database frames, float32, three copies: 1200 kB a row, so 1 GB holds 833 rows
    assert blocks.block_rows(100_000, 100_000, 1000) == 833
    assert blocks.block_rows(100_000, 100_000, 4000) == 3072  # a multiple of 1024
    assert blocks.block_rows(4541, 4541, 1024) == 4541  # KITTI 00 is one block: the dense path
    assert blocks.block_rows(10, 10**9, 1) == 1


def test_budget_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(blocks.BLOCK_MB_ENV, "2000")
    assert blocks.block_mb() == 2000.0
    monkeypatch.setenv(blocks.BLOCK_MB_ENV, "lots")
    with pytest.raises(ConfigError, match="SAFL_BLOCK_MB must be a number of MB > 0, got 'lots'"):
        blocks.block_mb()
    with pytest.raises(ConfigError, match="block size must be a number of MB > 0, got 0"):
        blocks.block_mb(0)


def test_bad_blocks_are_named() -> None:
    D = route_matrix(20, 20)
    with pytest.raises(ConfigError, match="block size must be a whole number of query rows >= 1, got 0"):
        blocks.match_rows(lambda a, b: D[a:b], 20, 20, [MatcherConfig()], block=0)
    bad = D.copy()
    bad[13, 4] = np.nan
    with pytest.raises(DataError, match=r"rows 10\.\.14: difference matrix has 1 NaN"):
        blocks.match_rows(lambda a, b: bad[a:b], 20, 20, [MatcherConfig()], block=5)
    with pytest.raises(DataError, match=r"rows 0\.\.4 of the difference matrix have shape \(5, 19\)"):
        blocks.match_rows(lambda a, b: D[a:b, :19], 20, 20, [MatcherConfig()], block=5)


def test_rows_held_stay_bounded() -> None:
    """The kept rows between blocks are the trajectory's reach, not the queries so far."""
    D = route_matrix(200, 30)
    held: list[int] = []
    real_advance = blocks._advance

    def spy(s: blocks._Stream, *args: object) -> tuple[np.ndarray, ...]:
        out = real_advance(s, *args)  # type: ignore[arg-type]
        held.append(len(s.rows))
        return out

    blocks._advance = spy  # type: ignore[assignment]
    try:
        cfg = dataclasses.replace(MatcherConfig(), trajectory="centred")
        blocks.match_rows(lambda a, b: D[a:b], 200, 30, [cfg], block=20)
    finally:
        blocks._advance = real_advance  # type: ignore[assignment]
    lo, hi = cfg.u_range()
    assert max(held[:-1]) == hi - lo


def test_aligned_blocks_of_the_default_distance_are_its_rows() -> None:
    """What the cell's bit-for-bit equality rests on: a 1024-row block of Eq. 4's distance is
    the same BLAS call as in the whole matrix, so the same numbers."""
    rng = np.random.default_rng(3)
    q = rng.standard_normal((2500, 32), dtype=np.float32)
    db = rng.standard_normal((300, 32), dtype=np.float32)
    whole = sqeuclidean(q, db)
    for a in (0, 1024, 2048):
        np.testing.assert_array_equal(sqeuclidean(q[a:a + 1024], db), whole[a:a + 1024])


class Exact:
    """A row-exact distance (a given matrix), so any block size must give the whole answer."""

    name = "exact"
    input_kind = "topview"
    cache_descriptors = False

    def __init__(self, D: np.ndarray, rowwise: bool = True) -> None:
        self.D = D
        self.rowwise_distance = rowwise
        self.calls: list[int] = []

    def describe(self, views: np.ndarray) -> np.ndarray:
        return np.asarray(views, dtype=np.float64)[:, None]

    def distance(self, q: np.ndarray, db: np.ndarray) -> np.ndarray:
        self.calls.append(len(q))
        return self.D[np.ix_(q[:, 0].astype(int), db[:, 0].astype(int))]


def _truth(n: int, revisit: bool):
    from safl_bench.evaluation.groundtruth import GroundTruth

    xy = np.c_[np.arange(n) * 3.0 % 90.0, np.zeros(n)]
    t = np.arange(n, dtype=float)
    return GroundTruth(xy, xy, t, t, tp_radius=4.0, fp_radius=20.0,
                       window_s=10.0 if revisit else None)


@pytest.mark.parametrize("revisit", [False, True])
def test_a_cell_in_small_blocks_scores_what_the_whole_matrix_scores(revisit: bool) -> None:
    from safl_bench.evaluation.cell import evaluate_method
    from safl_bench.matching.settings import MODES

    n = 120
    D = route_matrix(n, n, seed=4)
    frames = np.arange(n)
    kw = dict(revisit=revisit, context=10, config=presets.configure("paper"))
    whole_method, small_method = Exact(D), Exact(D)
    whole = evaluate_method(whole_method, frames, frames, _truth(n, revisit), **kw)
    small = evaluate_method(small_method, frames, frames, _truth(n, revisit), block_mb=0.01, **kw)
    assert max(small_method.calls) < n and len(whole_method.calls) == 2  # window rows + one block
    for mode in MODES:
        same(small.matches[mode], whole.matches[mode])
        np.testing.assert_array_equal(small.outcomes[mode].true_rank, whole.outcomes[mode].true_rank)
        for name, value in dataclasses.asdict(whole.metrics[mode]).items():
            np.testing.assert_array_equal(getattr(small.metrics[mode], name), value, err_msg=name)


def test_a_distance_that_is_not_rowwise_gets_the_whole_matrix() -> None:
    from safl_bench.evaluation.cell import _SAID_DENSE, evaluate_method

    n = 60
    method = Exact(route_matrix(n, n), rowwise=False)
    _SAID_DENSE.discard(Exact)
    with pytest.warns(UserWarning, match="'exact': its distance is not row-wise"):
        evaluate_method(method, np.arange(n), np.arange(n), _truth(n, False), block_mb=0.001)
    assert method.calls == [n]
