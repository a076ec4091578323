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

Describing is checkpointed: the views the cache lacks are described in chunks (`Chunking`), and
each finished chunk is written as its own shard before the next one starts, so an interrupted
describe (Ctrl-C, a killed job) loses at most the chunk in progress and the next call describes
only what is still missing. The format is unchanged (a chunk is a shard like any other), so
caches written before read the same. The chunks are sized by time, not only by count: the first
is small (it shows progress at once and measures the method's speed), later ones aim at
`Chunking.seconds` each (what an interrupt can cost), within `[first, most]` frames (`most` bounds
a chunk's memory and keeps fast methods from writing thousands of tiny shards). Descriptors are
those of one call for methods that describe each view independently of its batch, which the
cache assumes anyway; each shard keeps its own chunk's seconds per frame, so the cost returned
for views described over several runs is still the sum of what each frame cost.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench.common import progress
from safl_bench.common.atomic import atomic_path
from safl_bench.common.fingerprint import fingerprint
from safl_bench.common.parallel import Parallel
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


@dataclass(frozen=True)
class Chunking:
    """How `cached_describe` splits the views it must describe into checkpointed chunks.

    `first` frames first (progress shows at once; their time measures the method), then chunks
    of about `seconds` each at the speed of the chunk before, within `[first, most]` frames. 30 s
    bounds what an interrupt loses (BEVPlace, ~80 ms a frame on CPU, writes chunks of ~370
    frames) while each chunk is large enough that writing its shard costs nothing beside
    describing it; `most` = 1024 keeps a fast method's shards few and a chunk's batch in memory.
    `first == most` gives fixed chunks (what the tests use)."""

    first: int = 16
    seconds: float = 30.0
    most: int = 1024

    def next_size(self, seconds_per_frame: float) -> int:
        """Frames of the next chunk, after one that took `seconds_per_frame` a frame."""
        if seconds_per_frame <= 0:
            return self.most
        return int(min(self.most, max(self.first, self.seconds / seconds_per_frame)))


CHUNKING = Chunking()
"""The chunks of every cached describe (`cached_describe`'s default)."""


def _describe_job(method: Method, views: Any) -> tuple[np.ndarray, float]:
    """One chunk on a worker: its descriptors (float32) and the seconds they took there."""
    t0 = time.perf_counter()
    desc = np.asarray(method.describe(views), dtype=np.float32)
    return desc, time.perf_counter() - t0


def describe_chunks(method: Method, views: Any, parallel: Parallel,
                    on_chunk: Callable[[np.ndarray, np.ndarray, float], None] | None = None,
                    ) -> list[tuple[np.ndarray, float]]:
    """`method.describe` of `views` in chunks on `parallel`'s workers: (descriptors, seconds)
    per chunk, in the views' order. Chunks of at most `CHUNKING.most` frames, at least two per
    slot (so a slow worker does not hold the rest back). `on_chunk(positions, descriptors,
    seconds)` runs here as each chunk comes back (the cache writes its shard there); each
    chunk's frames go to the cell's progress. A chunk that fails stops the describe with its
    worker's error (a DataError)."""
    from safl_bench.common.parallel import run_jobs
    from safl_bench.errors import DataError

    n = len(views)
    size = max(1, min(CHUNKING.most, -(-n // (2 * parallel.slots()))))
    cuts = [np.arange(a, min(a + size, n)) for a in range(0, n, size)]

    def part(c: np.ndarray) -> Any:  # an array's rows, or a list's items (point clouds)
        return views[c] if isinstance(views, np.ndarray) else [views[int(i)] for i in c]

    def done(i: int, result: Any) -> None:
        if result.error is None:
            if on_chunk is not None:
                on_chunk(cuts[i], result.value[0], result.value[1])
            progress.advance(len(cuts[i]))

    results = run_jobs(_describe_job, [(method, part(c)) for c in cuts], parallel, on_done=done)
    failed = [r.error for r in results if r.error is not None]
    if failed:
        raise DataError(f"method {method.name!r}: describing failed on a worker: {failed[0]}")
    return [r.value for r in results]


def cached_describe(method: Method, views: Any, chunking: Chunking | None = None,
                    parallel: Parallel | None = None) -> tuple[np.ndarray, float, int]:
    """Descriptors of `views` (N, H, W) through the cache: (descriptors, seconds per frame as
    measured when they were described, frames described now).

    The views the cache lacks are described in chunks (`chunking`, default `CHUNKING`), each
    written as a shard as soon as it is done: an interrupt loses at most the chunk in progress,
    and calling again describes only the rest (module docstring). Reports the frames to the
    cell's progress (`safl_bench.common.progress`): those read from the cache at once, then
    each chunk as it is written. With `parallel`, the missing views are described on its
    workers instead (`describe_chunks`), each chunk written as a shard as it comes back."""
    views = np.asarray(views)
    policy = chunking or CHUNKING
    folder = cache_dir(method)
    keys = view_keys(views)
    index, shards, costs = _load(folder)
    found = [index.get(k.tobytes()) for k in keys]
    missing = np.array([i for i, f in enumerate(found) if f is None], dtype=np.int64)
    hit = np.array([f is not None for f in found], dtype=bool)
    rows = [shards[f[0]][f[1]] for f in found if f is not None]
    total = sum(costs[f[0]] for f in found if f is not None)
    out: np.ndarray | None = None
    if rows:
        out = np.empty((len(views), rows[0].shape[0]), dtype=np.float32)
        out[hit] = np.stack(rows)
    progress.advance(len(rows))
    start, size = 0, policy.first
    if parallel is not None and len(missing):
        def keep(at: np.ndarray, fresh: np.ndarray, seconds: float) -> None:
            nonlocal out, total
            chunk = missing[at]
            cost = seconds / len(chunk)
            _write_shard(folder, keys[chunk], fresh, cost)
            if out is None:
                out = np.empty((len(views), fresh.shape[1]), dtype=np.float32)
            out[chunk] = fresh
            total += cost * len(chunk)

        describe_chunks(method, views[missing], parallel, keep)
        start = len(missing)
    while start < len(missing):
        chunk = missing[start:start + size]
        t0 = time.perf_counter()
        fresh = np.asarray(method.describe(views[chunk]), dtype=np.float32)
        cost_now = (time.perf_counter() - t0) / len(chunk)
        _write_shard(folder, keys[chunk], fresh, cost_now)
        if out is None:
            out = np.empty((len(views), fresh.shape[1]), dtype=np.float32)
        out[chunk] = fresh
        total += cost_now * len(chunk)
        progress.advance(len(chunk))
        start += len(chunk)
        size = policy.next_size(cost_now)
    if out is None:  # no views at all
        out = np.asarray(method.describe(views), dtype=np.float32)
    return out, total / max(len(views), 1), len(missing)


def _write_shard(folder: Path, keys: np.ndarray, descriptors: np.ndarray, cost: float) -> None:
    """One chunk's shard, written atomically under the digest of its keys."""
    name = hashlib.sha256(keys.tobytes()).hexdigest()[:16]
    with atomic_path(folder / f"shard-{name}.npz") as tmp:
        np.savez(tmp, keys=keys, descriptors=descriptors, seconds_per_frame=np.float64(cost))
