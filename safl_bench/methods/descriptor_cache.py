"""On-disk cache of descriptors, for methods that are slow to describe (`Method.cache_descriptors`).

Keyed per view, not per task: a descriptor is stored under the digest of the view it describes
(BLAKE2b of its bytes, shape and dtype) in a folder of the method's configuration (the digest of
`Method.config()`, which holds every constructor parameter, the version and the weights' SHA-256).
So a rerun, a run with other matcher settings or another protocol on the same frames (BEVPlace's
protocol and the revisit protocol share frames of one sequence) reads what was described before,
and a changed view, parameter or weights file is a miss. Valid because methods describe each view
independently of its batch (`check_method` tests it).

Files: `<home>/descriptors/<method>-<config digest>/shard-<digest>.npz`, each holding `keys`
(n, 16) uint8, `descriptors` (n, D) float32 and `seconds_per_frame` (what describing them cost,
so throughput figures of cached runs stay the measured ones), written atomically; shards only
ever get added.
"""

from __future__ import annotations

import hashlib
import time
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench.common.atomic import atomic_path
from safl_bench.common.fingerprint import fingerprint
from safl_bench.methods.method import Method
from safl_bench.paths import home


def cache_dir(method: Method) -> Path:
    """The folder of `method`'s configuration."""
    return home() / "descriptors" / f"{method.name}-{fingerprint(method.config())}"


def view_keys(views: np.ndarray) -> np.ndarray:
    """(N, 16) uint8 digests of each view (its bytes, shape and dtype)."""
    views = np.ascontiguousarray(views)
    head = f"{views.shape[1:]}{views.dtype}".encode()
    out = np.empty((len(views), 16), dtype=np.uint8)
    for i, view in enumerate(views):
        digest = hashlib.blake2b(view.tobytes(), digest_size=16, person=b"safl-view")
        digest.update(head)
        out[i] = np.frombuffer(digest.digest(), dtype=np.uint8)
    return out


def _load(folder: Path) -> tuple[dict[bytes, tuple[int, int]], list[np.ndarray], list[float]]:
    index: dict[bytes, tuple[int, int]] = {}
    shards: list[np.ndarray] = []
    costs: list[float] = []
    for path in sorted(folder.glob("shard-*.npz")):
        try:
            with np.load(path) as data:
                keys, desc = data["keys"], data["descriptors"]
                cost = float(data["seconds_per_frame"])
        except (OSError, KeyError, ValueError):
            continue  # a damaged shard is a miss, described again
        s = len(shards)
        shards.append(desc)
        costs.append(cost)
        for row, key in enumerate(keys):
            index[key.tobytes()] = (s, row)
    return index, shards, costs


def cached_describe(method: Method, views: Any) -> tuple[np.ndarray, float, int]:
    """Descriptors of `views` (N, H, W) through the cache: (descriptors, seconds per frame as
    measured when they were described, frames described now)."""
    views = np.asarray(views)
    folder = cache_dir(method)
    keys = view_keys(views)
    index, shards, costs = _load(folder)
    found = [index.get(k.tobytes()) for k in keys]
    missing = np.array([i for i, f in enumerate(found) if f is None], dtype=np.int64)
    fresh = None
    cost_now = 0.0
    if len(missing):
        t0 = time.perf_counter()
        fresh = np.asarray(method.describe(views[missing]), dtype=np.float32)
        cost_now = (time.perf_counter() - t0) / len(missing)
        folder.mkdir(parents=True, exist_ok=True)
        name = hashlib.sha256(keys[missing].tobytes()).hexdigest()[:16]
        with atomic_path(folder / f"shard-{name}.npz") as tmp:
            np.savez(tmp, keys=keys[missing], descriptors=fresh,
                     seconds_per_frame=np.float64(cost_now))
    rows = [shards[f[0]][f[1]] for f in found if f is not None]
    dim = fresh.shape[1] if fresh is not None else rows[0].shape[0]
    out = np.empty((len(views), dim), dtype=np.float32)
    hit = np.array([f is not None for f in found], dtype=bool)
    if rows:
        out[hit] = np.stack(rows)
    if fresh is not None:
        out[missing] = fresh
    total = cost_now * len(missing) + sum(costs[f[0]] for f in found if f is not None)
    return out, total / max(len(views), 1), len(missing)
