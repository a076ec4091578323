"""Exact behaviour of one cell's describing and comparing (`safl_bench.evaluation.cell`) that the
mutation run found untested (issue #37, item 5): the database memo (`describe_database`,
`views_digest`), the `distance` setting, and the task's context queries in `evaluate_method`."""

from __future__ import annotations

from typing import Any

import numpy as np

from safl_bench.evaluation import cell as cell_module
from safl_bench.evaluation.cell import (
    EvaluationConfig,
    describe_database,
    difference_matrix,
    evaluate_method,
    views_digest,
)
from safl_bench.evaluation.groundtruth import GroundTruth


class Counting:
    """Descriptors are the views themselves (one row per view); the method's own distance is
    `D` (indexed by the views, frame numbers), which is not the descriptors' L2 distance."""

    name = "counting"
    input_kind = "topview"
    cache_descriptors = False

    def __init__(self, D: np.ndarray | None = None) -> None:
        self.D = D
        self.calls: list[int] = []

    def describe(self, views: np.ndarray) -> np.ndarray:
        self.calls.append(len(views))
        return np.asarray(views, dtype=np.float64).reshape(len(views), -1)

    def distance(self, q: np.ndarray, db: np.ndarray) -> np.ndarray:
        assert self.D is not None
        return self.D[np.ix_(q[:, 0].astype(int), db[:, 0].astype(int))]


def counting(D: np.ndarray | None = None) -> Any:
    """A `Counting` method, typed as any `Method`."""
    return Counting(D)


def line_truth(n: int) -> GroundTruth:
    xy = np.c_[np.arange(n, dtype=float), np.zeros(n)]
    t = np.arange(n, dtype=float)
    return GroundTruth(xy, xy, t, t, tp_radius=1.0, fp_radius=1.0)


def test_views_digest_tells_views_apart_by_bytes_shape_and_dtype() -> None:
    views = np.arange(6.0)
    assert views_digest(views) == views_digest(views.copy()) == views_digest(list(views))
    assert len(views_digest(views)) == 32  # 16 bytes, hex
    others = [views + 1, views.reshape(3, 2), views.astype(np.float32), np.arange(6)]
    digests = {views_digest(v) for v in [views, *others]}
    assert len(digests) == 5


def test_database_descriptors_are_described_once_per_method_and_views() -> None:
    memo: cell_module.DatabaseMemo = {}
    m, other = counting(), counting()
    db = np.arange(6.0)
    d1, s1 = describe_database(m, db, memo)
    d2, s2 = describe_database(m, db.copy(), memo)  # equal views in another array: reused
    assert m.calls == [6] and d2 is d1 and s2 == s1
    describe_database(other, db, memo)  # another method: its own descriptors
    assert other.calls == [6] and len(memo) == 2
    d3, _ = describe_database(m, db + 1, memo)  # other views: described
    assert m.calls == [6, 6] and d3[:, 0].tolist() == (db + 1).tolist()
    # no memo, or views that are not one array: described every time
    describe_database(m, db, None)
    describe_database(m, list(db), memo)
    describe_database(m, list(db), memo)
    assert m.calls == [6] * 5 and len(memo) == 3


def test_the_memo_keeps_its_last_entries() -> None:
    memo: cell_module.DatabaseMemo = {}
    m = counting()
    limit = cell_module._MEMO_LIMIT
    for k in range(limit + 1):
        describe_database(m, np.arange(3.0) + 10 * k, memo)
    assert len(memo) == limit and len(m.calls) == limit + 1
    describe_database(m, np.arange(3.0) + 10 * limit, memo)  # the newest: kept
    assert len(m.calls) == limit + 1
    describe_database(m, np.arange(3.0), memo)  # the oldest: dropped, described again
    assert len(m.calls) == limit + 2 and len(memo) == limit


def test_the_distance_setting_chooses_the_comparison() -> None:
    D = np.full((4, 4), 7.0)
    m = counting(D)
    views = np.arange(4.0)
    own, _, n = difference_matrix(m, views, views, "method")
    np.testing.assert_array_equal(own, D)
    plain, _, _ = difference_matrix(m, views, views, "euclidean")
    np.testing.assert_array_equal(plain, np.abs(np.subtract.outer(views, views)))
    assert n == 8


def test_evaluate_method_uses_the_configured_distance_the_memo_and_the_context() -> None:
    n = 8
    D = np.abs(np.subtract.outer(np.arange(n, dtype=float), np.arange(n, dtype=float)))
    D[3, 7] = -1.0  # by its own distance the method matches query 3 to frame 7: wrong
    truth = line_truth(n)
    views = np.arange(float(n))
    own = evaluate_method(counting(D), views, views, truth)
    assert own.matches["single_frame"].index[3] == 7
    plain = evaluate_method(counting(D), views, views, truth,
                            config=EvaluationConfig(distance="euclidean"))
    assert plain.matches["single_frame"].index.tolist() == list(range(n))
    # the memo passes through: the database is described once for two cells
    m = counting(D)
    memo: cell_module.DatabaseMemo = {}
    evaluate_method(m, views, views, truth, memo=memo)
    evaluate_method(m, views, views, truth, memo=memo)
    assert m.calls == [n, n, n] and len(memo) == 1
    # the task's first context queries are matched but not scored
    ev = evaluate_method(counting(D), views, views, truth, context=3)
    assert len(ev.matches["sequence"].index) == n
    assert len(ev.outcomes["single_frame"].label) == n - 3
    assert ev.metrics["single_frame"].n_queries == n - 3
    np.testing.assert_array_equal(ev.outcomes["sequence"].confidence,
                                  ev.matches["sequence"].confidence[3:])
