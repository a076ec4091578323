"""The descriptor cache: a rerun, a subset or another protocol on the same views describes nothing
again; another configuration or a changed view is a miss."""

from __future__ import annotations

import numpy as np

from safl_bench.descriptor_cache import cache_dir, cached_describe
from safl_bench.method import Method, as_topview


class Counting(Method):
    name = "counting"
    version = "1"

    def __init__(self, scale: float = 1.0) -> None:
        self.scale = scale
        self.described = 0

    def describe(self, maps):  # type: ignore[no-untyped-def]
        arr = as_topview(maps)
        self.described += len(arr)
        return (arr.reshape(len(arr), -1)[:, :4] * self.scale).astype(np.float32)


def test_views_are_described_once(safl_home) -> None:
    views = np.random.default_rng(0).random((6, 8, 8)).astype(np.float32)
    method = Counting()
    first, cost, n = cached_describe(method, views)
    assert n == 6 and method.described == 6 and cost >= 0
    again, _, n = cached_describe(method, views[[4, 1, 2]])  # a subset, in another order
    assert n == 0 and method.described == 6
    np.testing.assert_array_equal(again, first[[4, 1, 2]])
    changed = views.copy()
    changed[3, 0, 0] = 0.5
    mixed, _, n = cached_describe(method, changed)
    assert n == 1 and method.described == 7  # only the changed view
    np.testing.assert_array_equal(mixed, method.describe(changed))
    other = Counting(scale=2.0)
    assert cache_dir(other) != cache_dir(method)
    _, _, n = cached_describe(other, views)
    assert n == 6
    (next(cache_dir(method).glob("shard-*.npz"))).write_bytes(b"damaged")
    redone, _, _ = cached_describe(method, views)  # a damaged shard is a miss, not an error
    np.testing.assert_array_equal(redone, first)


class Cached(Counting):
    name = "counting_cached"
    cache_descriptors = True


def test_the_evaluation_reads_cached_descriptors_for_methods_that_ask(safl_home) -> None:
    from safl_bench.evaluation import difference_matrix

    views = np.random.default_rng(1).random((5, 8, 8)).astype(np.float32)
    method = Cached()
    D1, _, n = difference_matrix(method, views[:2], views)
    D2, _, _ = difference_matrix(method, views[:2], views)
    assert method.described == 5 and n == 7  # the queries are database views: described once
    np.testing.assert_array_equal(D1, D2)
    plain = Counting()
    difference_matrix(plain, views[:2], views)
    assert plain.described == 7  # no cache unless asked
