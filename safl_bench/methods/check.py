"""`check_method`: the conformance checks a method must pass (descriptor or retrieval kind).

Meant for plug-in authors' own test suites as much as for ours::

    from safl_bench.methods.check import check_method

    def test_my_method_conforms():
        check_method(MyMethod(small_config=True))

A retrieval method (`safl_bench.methods.retrieval`) gets `RETRIEVAL_CHECKS` instead of the
describe/distance ones: `retrieve` returns a well-formed `Retrieval`, leaves its input alone,
answers every query, gives each view back as its own best candidate when the database holds it
(self-retrieval), returns only earlier frames when told the queries are the database frames
(``same_frames``), and answers the same twice (unless it declares ``deterministic = False``).

Every failed check raises `MethodCheckError` (an `AssertionError` and a `SaflError`) whose
message starts with the check's name, e.g. ``[describe-dtype] ...``.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from safl_bench.errors import SaflError
from safl_bench.methods.method import INPUT_KINDS, Method

CHECKS: tuple[str, ...] = (
    "attributes",
    "params",
    "fit-returns-self",
    "describe-shape",
    "describe-dtype",
    "describe-finite",
    "input-unchanged",
    "determinism",
    "batch-independence",
    "distance-shape",
    "distance-finite",
    "distance-nonnegative",
    "self-distance-minimal",
    "distance-rowwise",
)

RETRIEVAL_CHECKS: tuple[str, ...] = (
    "attributes",
    "params",
    "fit-returns-self",
    "retrieve-shape",
    "input-unchanged",
    "self-retrieval",
    "same-frames-earlier",
    "determinism",
)


class MethodCheckError(SaflError, AssertionError):
    """A conformance check failed; `check` names it."""

    def __init__(self, check: str, message: str) -> None:
        super().__init__(f"[{check}] {message}")
        self.check = check


def _fail(check: str, message: str) -> None:
    raise MethodCheckError(check, message)


def sample_views(input_kind: str, n: int = 8, size: int = 64, seed: int = 0) -> Any:
    """Random but structured views for the checks: blobs on top-view maps, or point clouds."""
    rng = np.random.default_rng(seed)
    if input_kind == "points":
        return [
            (rng.normal(size=(int(rng.integers(200, 600)), 3)) * [20.0, 20.0, 1.5]).astype(np.float32)
            for _ in range(n)
        ]
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32)
    maps = np.zeros((n, size, size), np.float32)
    for i in range(n):
        for _ in range(6):
            cy, cx = rng.uniform(0, size, 2)
            r = rng.uniform(2, size / 6)
            maps[i] = np.maximum(maps[i], np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * r * r)))
        maps[i] += rng.uniform(0, 0.1, (size, size)).astype(np.float32)
    return np.clip(maps, 0.0, 1.0)


def _take(views: Any, idx: Any) -> Any:
    if isinstance(views, np.ndarray):
        return views[idx]
    if isinstance(idx, slice):
        return views[idx]
    return [views[i] for i in idx]


def _copy(views: Any) -> Any:
    return views.copy() if isinstance(views, np.ndarray) else [v.copy() for v in views]


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b)
    return len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


def check_method(
    method: Method | type[Method],
    *,
    views: Any = None,
    fit: bool = True,
    rtol: float = 1e-4,
) -> Method:
    """Run every check in `CHECKS` on `method` (an instance, or a class built with defaults).

    `views` replaces the generated sample views (must be what `input_kind` says); `fit=False`
    skips `fit` (for an already trained method); `rtol` bounds batch-size dependence relative to
    the descriptors' scale. Returns the (fitted) method; raises MethodCheckError on failure.
    """
    if isinstance(method, type):
        if not issubclass(method, Method):
            _fail("attributes", f"{method!r} is not a subclass of safl_bench.methods.method.Method")
        method = method()
    if not isinstance(method, Method):
        _fail("attributes", f"{method!r} is not a safl_bench.methods.method.Method instance")
    cls = type(method)
    label = f"{cls.__name__} ({method.name!r})"

    # attributes
    if not isinstance(method.name, str) or not method.name:
        _fail("attributes", f"{label}: class attribute `name` must be a non-empty string")
    if not isinstance(method.version, str) or not method.version:
        _fail("attributes", f"{label}: class attribute `version` must be a non-empty string")
    if method.input_kind not in INPUT_KINDS:
        _fail("attributes", f"{label}: input_kind must be one of {INPUT_KINDS}, got {method.input_kind!r}")

    # params: get_params round-trips through the constructor and config() is JSON
    try:
        params = method.get_params()
        clone = cls(**params)
        if clone.get_params().keys() != params.keys():
            _fail("params", f"{label}: get_params() of a clone differs: {clone.get_params()} vs {params}")
        json.dumps(method.config())
    except MethodCheckError:
        raise
    except Exception as exc:
        _fail("params", f"{label}: get_params()/constructor/config() failed: {type(exc).__name__}: {exc}")

    if views is None:
        views = sample_views(method.input_kind)
    if getattr(method, "kind", "descriptor") == "retrieval":
        return _check_retrieval(method, views, label, fit)
    n = len(views)
    if n < 4:
        _fail("describe-shape", f"{label}: need at least 4 sample views, got {n}")
    original = _copy(views)

    if fit:
        result = method.fit(views)
        if result is not method:
            _fail("fit-returns-self", f"{label}: fit() must return self, returned {type(result).__name__}")
        if not _same(views, original):
            _fail("input-unchanged", f"{label}: fit() modified its input in place")

    desc = method.describe(views)
    if not isinstance(desc, np.ndarray):
        _fail("describe-shape", f"{label}: describe() must return a numpy array, got {type(desc).__name__}")
    if desc.ndim != 2 or desc.shape[0] != n or desc.shape[1] < 1:
        _fail("describe-shape", f"{label}: describe() of {n} views must give (N={n}, D>=1), got {desc.shape}")
    if desc.dtype != np.float32:
        _fail("describe-dtype", f"{label}: descriptors must be float32, got {desc.dtype}")
    if not np.isfinite(desc).all():
        _fail("describe-finite", f"{label}: descriptors contain NaN or inf")
    if not _same(views, original):
        _fail("input-unchanged", f"{label}: describe() modified its input in place")

    again = method.describe(views)
    if not np.array_equal(desc, again):
        _fail("determinism", f"{label}: describe() twice on the same views gave different descriptors "
              f"(max diff {np.abs(desc.astype(np.float64) - again).max():g})")

    scale = float(np.abs(desc).max()) or 1.0
    tol = rtol * scale + 1e-7
    singles = np.concatenate([method.describe(_take(views, slice(i, i + 1))) for i in range(n)])
    order = np.arange(n)[::-1].copy()
    reversed_desc = method.describe(_take(views, order))[order]
    for other, how in ((singles, "one view at a time"), (reversed_desc, "in reverse order")):
        if other.shape != desc.shape:
            _fail("batch-independence", f"{label}: describing {how} gave shape {other.shape}, expected {desc.shape}")
        diff = float(np.abs(other.astype(np.float64) - desc).max())
        if diff > tol:
            _fail("batch-independence", f"{label}: describing {how} changed descriptors by {diff:g} (> {tol:g})")

    q, db = desc[: n // 2], desc
    dist = np.asarray(method.distance(q, db))
    if dist.shape != (len(q), len(db)):
        _fail("distance-shape", f"{label}: distance(queries[{len(q)}], database[{len(db)}]) gave {dist.shape}")
    if not np.issubdtype(dist.dtype, np.floating):
        _fail("distance-shape", f"{label}: distance must be a float array, got {dist.dtype}")
    if not np.isfinite(dist).all():
        _fail("distance-finite", f"{label}: distance matrix contains NaN or inf")
    if (dist < 0).any():
        _fail("distance-nonnegative", f"{label}: distance matrix has negative entries (min {dist.min():g})")
    own = dist[np.arange(len(q)), np.arange(len(q))]
    dscale = float(dist.max()) or 1.0
    if (own > dist.min(axis=1) + 1e-5 * dscale).any():
        _fail("self-distance-minimal", f"{label}: a view is not closest to itself (distance to itself "
              f"{own.max():g} exceeds the row minimum)")
    if getattr(method, "rowwise_distance", True) and len(q) > 1:
        parts = np.concatenate([np.asarray(method.distance(q[i:i + 1], db)) for i in range(len(q))])
        # within rounding: a BLAS product may round a row differently for another number of
        # rows; the matcher's blocks are whole multiples of the distance's chunk (matching.blocks)
        off = float(np.abs(parts.astype(np.float64) - dist).max()) if parts.shape == dist.shape \
            else np.inf
        if off > 1e-5 * dscale:
            _fail("distance-rowwise", f"{label}: the distance of one query at a time differs from "
                  f"that of all queries at once (by {off:g}), so the matcher's query blocks would "
                  f"change matches; make each row depend on its query only, or set "
                  f"rowwise_distance = False")
    return method


def _check_retrieval(method: Method, views: Any, label: str, fit: bool) -> Method:
    """`RETRIEVAL_CHECKS` after attributes and params (module docstring)."""
    from safl_bench.methods.retrieval import Retrieval, is_deterministic

    n = len(views)
    if n < 4:
        _fail("retrieve-shape", f"{label}: need at least 4 sample views, got {n}")
    original = _copy(views)
    if fit:
        result = method.fit(views)
        if result is not method:
            _fail("fit-returns-self", f"{label}: fit() must return self, returned {type(result).__name__}")
    retrieve = method.retrieve  # type: ignore[attr-defined]

    def answer(queries: Any, database: Any, **kw: Any) -> Retrieval:
        out = retrieve(queries, database, **kw)
        if not isinstance(out, Retrieval):
            _fail("retrieve-shape", f"{label}: retrieve() must return a Retrieval, got {type(out).__name__}")
        try:
            return out.checked(len(queries), len(database), label)
        except SaflError as exc:
            _fail("retrieve-shape", str(exc))
        raise AssertionError  # unreachable

    first = answer(views, views)
    if not _same(views, original):
        _fail("input-unchanged", f"{label}: retrieve() modified its input in place")
    ranked = [int(first.index[i, np.argmax(first.confidence[i])])
              if (first.index[i] >= 0).any() else -1 for i in range(n)]
    wrong = [i for i in range(n) if ranked[i] != i]
    if wrong:
        _fail("self-retrieval", f"{label}: with the database holding the query's own view, query "
              f"{wrong[0]}'s most confident candidate is {ranked[wrong[0]]}, not itself "
              f"({len(wrong)} of {n} queries)")
    limit = np.arange(n, dtype=np.int64)
    online = answer(views, views, db_limit=limit, same_frames=True)
    late = [(i, int(j)) for i in range(n) for j in online.index[i] if j >= i]
    if late:
        _fail("same-frames-earlier", f"{label}: with same_frames, query {late[0][0]} lists frame "
              f"{late[0][1]}, not an earlier one (the harness would drop it; an online method "
              "must not see later frames)")
    if is_deterministic(method):
        again = answer(views, views)
        if not (np.array_equal(first.index, again.index)
                and np.array_equal(first.confidence, again.confidence)):
            _fail("determinism", f"{label}: retrieve() twice on the same views answered differently")
    return method
