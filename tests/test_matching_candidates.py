"""The candidate search (`safl_bench.matching.candidates`): with every frame a candidate it finds
the exact matcher's matches; with few it reports only candidates; bad input is named."""

from __future__ import annotations

import builtins

import numpy as np
import pytest

from safl_bench.errors import ConfigError, DataError
from safl_bench.matching import candidates, presets
from safl_bench.matching.matcher import MatcherConfig, match
from safl_bench.matching.settings import EvaluationConfig
from safl_bench.methods.distance import euclidean, sqeuclidean

pytest.importorskip("faiss")


def route(nq: int = 120, ndb: int = 100, seed: int = 0, noise: float = 0.6):
    """A database that drifts (a random walk) and queries that drive a stretch of it again."""
    rng = np.random.default_rng(seed)
    db = np.cumsum(rng.standard_normal((ndb, 8)), axis=0).astype(np.float32)
    truth = (np.arange(nq) * 3 // 4 + 7) % ndb
    q = db[truth] + noise * rng.standard_normal((nq, 8)).astype(np.float32)
    return q, db, truth


CONFIGS = [presets.get("paper-r10").config.sequence, presets.get("authors").config.sequence,
           MatcherConfig(trajectory="centred", score="ratio", out_of_range="clip"),
           MatcherConfig(enhance_window=0), MatcherConfig(method="single_frame", ds=0,
                                                          enhance_window=0)]


@pytest.mark.parametrize("cfg", CONFIGS, ids=lambda c: f"{c.preset}-{c.trajectory}-{c.score}")
@pytest.mark.parametrize("revisit", [False, True])
def test_every_frame_a_candidate_is_the_exact_matcher(cfg: MatcherConfig, revisit: bool) -> None:
    q, db, _ = route()
    limit = np.clip(np.arange(len(q)) - 20, 0, len(db)).astype(np.int64) if revisit else None
    root = cfg.preset == "authors"
    D = (euclidean if root else sqeuclidean)(q, db, dtype="float64")
    exact = match(D, MatcherConfig(**{**cfg.to_dict(), "dtype": "float64"}), db_limit=limit)
    cand = candidates.nearest(q, db, len(db), db_limit=limit)
    got = candidates.match_candidates(q, db, cand, cfg, db_limit=limit, root=root)
    np.testing.assert_array_equal(got.index, exact.index)
    np.testing.assert_array_equal(got.velocity, exact.velocity)
    ok = np.isfinite(exact.score)
    if cfg.score == "min":  # the same up to the shift, which is the lowest value seen here
        gap = got.score[ok] - exact.score[ok]
        np.testing.assert_allclose(gap, gap[0], atol=1e-4)  # float32 products


@pytest.mark.parametrize("dim", [8, 37, 1024])
def test_a_product_has_the_same_bits_in_every_slot_of_the_tile(dim: int) -> None:
    """The kernel makes each (row, frame) product in whichever tile slot a group puts it;
    the value must not depend on the slot."""
    rng = np.random.default_rng(dim)
    q = rng.standard_normal((5, dim)).astype(np.float32)
    db = rng.standard_normal((5, dim)).astype(np.float32)
    seen = set()
    for i in range(4):
        for m in range(4):
            rows = [1 + (x + i) % 4 for x in range(4)]
            cols = [1 + (x + m) % 4 for x in range(4)]
            rows[i], cols[m] = 0, 0
            out = np.zeros((4, 4), np.float32)
            candidates._tile(q, *rows, db, *cols, out, 0)
            seen.add(out[i, m].tobytes())
            np.testing.assert_allclose(out[i, m], q[0] @ db[0], rtol=1e-5)
    assert len(seen) == 1


def test_few_candidates_report_only_candidates_and_respect_the_limit() -> None:
    q, db, truth = route(noise=0.3)
    limit = np.clip(np.arange(len(q)) - 3, 0, len(db)).astype(np.int64)
    cand = candidates.nearest(q, db, 5, db_limit=limit)
    assert ((cand.index < limit[:, None]) | (cand.index == -1)).all()
    step = np.diff(np.where(cand.index >= 0, cand.index, 10**9), axis=1)
    assert ((step > 0) | (cand.index[:, 1:] == -1)).all()  # ascending, padding last
    # the k nearest allowed frames, as a brute-force search finds them
    D = sqeuclidean(q, db, dtype="float64")
    for i in range(len(q)):
        allowed = np.argsort(D[i, :limit[i]], kind="stable")[:5]
        assert set(cand.index[i][cand.index[i] >= 0]) == set(allowed)
    got = candidates.match_candidates(q, db, cand, MatcherConfig(), db_limit=limit)
    for i, j in enumerate(got.index):
        assert j == -1 or j in cand.index[i]
    found = (got.index >= 0) & (truth < limit)
    assert np.mean(np.abs(got.index[found] - truth[found]) <= 1) > 0.8


def test_the_ivf_index_gives_the_same_candidates_every_run() -> None:
    q, db, _ = route(nq=300, ndb=2000, seed=2)
    a = candidates.nearest(q, db, 10, index="ivf")
    b = candidates.nearest(q, db, 10, index="ivf")
    np.testing.assert_array_equal(a.index, b.index)
    exact = candidates.nearest(q, db, 10)
    assert np.mean([len(set(x) & set(y)) / 10 for x, y in zip(a.index, exact.index, strict=True)]) > 0.5


def test_candidate_ranks_follow_the_tie_rule() -> None:
    cand = candidates.Candidates(np.array([[2, 5, 9], [1, 3, -1]]),
                                 np.array([[4.0, 1.0, 1.0], [2.0, 3.0, np.inf]]))
    ranks = candidates.candidate_ranks(cand, [np.array([9]), np.array([7])], not_found=999)
    assert ranks.tolist() == [2, 999]  # frame 5 ties at 1.0 with a lower index; 7 not returned


def test_bad_input_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    q, db, _ = route()
    with pytest.raises(ConfigError, match="candidates=101 is more than the database's 100 frames"):
        candidates.nearest(q, db, 101)
    with pytest.raises(ConfigError, match="candidates must be a whole number of frames >= 1, got 0"):
        candidates.nearest(q, db, 0)
    with pytest.raises(ConfigError, match="index must be one of 'flat', 'ivf', got 'hnsw'"):
        candidates.nearest(q, db, 3, index="hnsw")
    bad = q.copy()
    bad[4, 2] = np.nan
    with pytest.raises(DataError, match="query descriptors contain NaN or infinite values"):
        candidates.nearest(bad, db, 3)
    with pytest.raises(DataError, match="descriptors differ in length: 8 vs 7"):
        candidates.nearest(q, db[:, :7], 3)
    with pytest.raises(ConfigError, match="candidates must be null"):
        EvaluationConfig(candidates=2.5)  # type: ignore[arg-type]
    real_import = builtins.__import__

    def no_faiss(name: str, *args: object, **kw: object) -> object:
        if name == "faiss":
            raise ImportError("no faiss")
        return real_import(name, *args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(builtins, "__import__", no_faiss)
    with pytest.raises(ConfigError, match=r"candidate search needs FAISS.*safl-bench\[faiss\]"):
        candidates.nearest(q, db, 3, index="ivf")
    assert candidates.nearest(q, db, 3).index.shape == (len(q), 3)  # the flat search is our own


def test_records_carry_the_candidate_settings_only_when_set() -> None:
    exact = EvaluationConfig().to_dict()["evaluation"]
    assert "candidates" not in exact and "index" not in exact
    cfg = presets.configure("paper", {"candidates": 10, "index": "ivf"})
    assert cfg.to_dict()["evaluation"]["candidates"] == 10
    assert EvaluationConfig.from_dict(cfg.to_dict()) == cfg
    assert presets.label(cfg) == "paper+candidates=10,index=ivf"


@pytest.mark.parametrize("cfg", CONFIGS, ids=lambda c: f"{c.preset}-{c.trajectory}-{c.score}")
@pytest.mark.parametrize("revisit", [False, True])
def test_the_flat_pass_over_rows_is_the_exact_matcher_in_any_blocks(cfg: MatcherConfig,
                                                                      revisit: bool) -> None:
    q, db, _ = route()
    limit = np.clip(np.arange(len(q)) - 20, 0, len(db)).astype(np.int64) if revisit else None
    D = sqeuclidean(q, db, dtype="float64")
    exact = match(D, MatcherConfig(**{**cfg.to_dict(), "dtype": "float64"}), db_limit=limit)
    first = None
    for block in (None, 1, 7, 50):
        _, (got,), _ = candidates.search_rows(lambda a, b: D[a:b], len(q), len(db), len(db),
                                              [cfg], db_limit=limit, block=block)
        np.testing.assert_array_equal(got.index, exact.index)
        np.testing.assert_array_equal(got.velocity, exact.velocity)
        if first is None:
            first = got
        np.testing.assert_array_equal(got.score, first.score)  # blocks change no bit


@pytest.mark.parametrize("k", [1, 5, 32, 33, 300])
def test_the_flat_search_keeps_the_k_lowest_allowed_frames_ties_to_the_lower(k: int) -> None:
    rng = np.random.default_rng(k)
    X = rng.integers(0, 20, (40, 300)).astype(np.float32)  # many ties
    lim = rng.integers(0, 301, 40)
    idx, dist = candidates._nearest_rows(X, lim, k)
    for r in range(40):
        want = np.sort(np.argsort(X[r, :lim[r]], kind="stable")[:k])
        got = idx[r][idx[r] >= 0]
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(dist[r][:len(got)], X[r, got])
