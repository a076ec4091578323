"""On-disk cache of rendered views, keyed by everything that changes them.

Key: (source fingerprint, sequence, MapConfig, frames, condition, seed, kind). The seed only
matters for noisy conditions, so clean views are shared by all seeds. Files live under
`paths.map_cache_dir()/<source kind>-<sequence>/` as compressed `.npz`, written atomically:

    topview-<condition>-<key>.npz   maps (F, size, size) float32, meta (JSON)
    points-<condition>-<key>.npz    points (sum M_i, 3) float32, offsets (F + 1,) int64, meta

A file written by a parallel `prepare` holds, instead of those arrays, the compressed chunks the
workers made, in frame order, as members part-0000.npz, part-0001.npz, ... (each a compressed
`.npz` of the arrays above for its frames) beside `meta`; it loads to the same views.

Tasks call `load_views`; `prepare` renders many conditions and kinds in one pass over the scans.
Sources whose views are cheaper to render than to read back (`DataSource.cache_views` false: an
image folder) are not cached here: `load_views` renders them each time and `prepare` does nothing.
"""

from __future__ import annotations

import dataclasses
import io
import json
import zipfile
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench.common.atomic import atomic_path
from safl_bench.common.fingerprint import fingerprint, to_jsonable
from safl_bench.common.parallel import JobResult, Parallel, run_jobs
from safl_bench.common.progress import report
from safl_bench.errors import ConfigError, DataError
from safl_bench.paths import map_cache_dir
from safl_bench.sources import DataSource
from safl_bench.views.mapbuild import KINDS, check_frames
from safl_bench.views.mapconfig import MapConfig
from safl_bench.views.noise import Condition, sample_offsets
from safl_bench.views.render import build_views as render_views

CACHE_VERSION = 1  # bump when the rendering code changes what a key's file holds
#: per view kind, bumped when only that kind's rendering changes (points 2: cropped to the
#: top view's window)
KIND_VERSIONS = {"topview": 1, "points": 2}


def cache_key(
    source: DataSource, sequence: str, config: MapConfig | None, frames: np.ndarray,
    condition: Condition, seed: int, kind: str,
) -> str:
    """The cache key of one set of views."""
    kind_version = KIND_VERSIONS.get(kind, 1)
    bumped = () if kind_version == 1 else (kind_version,)  # keys of unchanged kinds stay valid
    return fingerprint(
        CACHE_VERSION, *bumped, source.fingerprint(sequence), str(sequence), config,
        np.asarray(frames, dtype=np.int64), condition, None if condition.is_clean else int(seed), kind,
    )


def cache_path(
    source: DataSource, sequence: str, config: MapConfig | None, frames: np.ndarray,
    condition: Condition, seed: int, kind: str,
) -> Path:
    """Where the views of that key are (or will be) cached."""
    key = cache_key(source, sequence, config, frames, condition, seed, kind)
    return map_cache_dir() / f"{source.kind}-{sequence}" / f"{kind}-{condition.name}-{key}.npz"


def _meta(source: DataSource, sequence: str, config: MapConfig | None, frames: np.ndarray,
          condition: Condition, seed: int, kind: str) -> str:
    return json.dumps(to_jsonable({
        "source": source.label, "root": str(source.root), "sequence": sequence, "config": config,
        "frames": len(frames), "condition": condition.name, "seed": seed, "kind": kind,
        "version": CACHE_VERSION, "kind_version": KIND_VERSIONS.get(kind, 1),
    }), sort_keys=True)


def _write_views(target: Path | io.BytesIO, views: np.ndarray | list[np.ndarray], meta: str | None) -> None:
    """The compressed `.npz` of one set of views (and `meta`, if given)."""
    arrays: dict[str, Any] = {}
    if isinstance(views, np.ndarray):
        arrays["maps"] = views.astype(np.float32)
    else:
        lengths = np.array([len(v) for v in views], dtype=np.int64)
        arrays["points"] = np.concatenate(views).astype(np.float32) if views else np.zeros((0, 3), np.float32)
        arrays["offsets"] = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    if meta is not None:
        arrays["meta"] = np.array(meta)
    np.savez_compressed(target, **arrays)


def _save(path: Path, views: np.ndarray | list[np.ndarray], meta: str) -> None:
    with atomic_path(path) as tmp:
        _write_views(tmp, views, meta)


def _compress(views: np.ndarray | list[np.ndarray]) -> bytes:
    """One chunk's views as compressed `.npz` bytes (made on a worker, joined by `_save_parts`)."""
    buffer = io.BytesIO()
    _write_views(buffer, views, None)
    return buffer.getvalue()


def _save_parts(path: Path, parts: Sequence[bytes], meta: str) -> None:
    """The cache file of views that workers compressed chunk by chunk: the chunks are stored as
    they are (no second compression), in frame order."""
    with atomic_path(path) as tmp:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED, allowZip64=True) as archive:
            with archive.open("meta.npy", "w") as fh:
                np.lib.format.write_array(fh, np.array(meta))
            for i, part in enumerate(parts):
                archive.writestr(f"part-{i:04d}.npz", part)


def _views(data: np.lib.npyio.NpzFile, kind: str) -> np.ndarray | list[np.ndarray]:
    if kind == "topview":
        return np.asarray(data["maps"], dtype=np.float32)
    points, offsets = data["points"], data["offsets"]
    return [points[offsets[i] : offsets[i + 1]] for i in range(len(offsets) - 1)]


def _load(path: Path, kind: str) -> np.ndarray | list[np.ndarray]:
    with np.load(path) as data:
        parts = sorted(name for name in data.files if name.startswith("part-"))
        if not parts:
            return _views(data, kind)
        chunks = []
        for name in parts:
            with np.load(io.BytesIO(data[name])) as part:
                chunks.append(_views(part, kind))
    if kind == "topview":
        return np.concatenate(chunks)
    return [view for chunk in chunks for view in chunk]


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ConfigError(f"view kind must be one of {', '.join(KINDS)}, got {kind!r}")


def prepare(
    source: DataSource,
    sequence: str,
    config: MapConfig | None,
    *,
    frames: np.ndarray,
    conditions: Iterable[Condition],
    seed: int,
    kinds: Sequence[str] = ("topview",),
    progress: bool = True,
    parallel: Parallel | None = None,
) -> dict[tuple[Condition, str], Path]:
    """Make sure the views of every (condition, kind) are cached; render the missing ones in
    one pass over the scans. Returns {(condition, kind): cache file}.

    With `parallel` (local workers or Ray) the frames are split into contiguous chunks rendered
    and compressed on the workers, each from a fresh local map of the `window` scans before its
    first frame (the map at a frame depends only on those scans, so the views are the serial
    ones); this process stores the compressed chunks in the cache files."""
    return prepare_sequences(source, {sequence: frames}, config, conditions=conditions, seed=seed,
                             kinds=kinds, progress=progress, parallel=parallel)[str(sequence)]


@dataclasses.dataclass
class _Plan:
    """What `prepare_sequences` must render for one sequence."""

    sequence: str
    frames: np.ndarray
    paths: dict[tuple[Condition, str], Path]
    missing: list[tuple[Condition, str]]
    offsets: dict[str, np.ndarray | None]  # per condition to render
    kinds: list[str]  # kinds to render
    meta: dict[tuple[Condition, str], str]


def _plan(source: DataSource, sequence: str, frames: np.ndarray, config: MapConfig | None,
          conds: list[Condition], seed: int, kinds: Sequence[str]) -> _Plan:
    frames = check_frames(frames, len(source.sequence(sequence)), sequence)
    paths = {(c, k): cache_path(source, sequence, config, frames, c, seed, k) for c in conds for k in kinds}
    missing = [ck for ck, p in paths.items() if not p.is_file()]
    todo_conds = list(dict.fromkeys(c for c, _ in missing))
    return _Plan(
        sequence, frames, paths, missing,
        offsets={c.name: None if c.is_clean else sample_offsets(len(frames), c, seed) for c in todo_conds},
        kinds=[k for k in kinds if any(kk == k for _, kk in missing)],
        meta={ck: _meta(source, sequence, config, frames, ck[0], seed, ck[1]) for ck in missing},
    )


def prepare_sequences(
    source: DataSource,
    frames: Mapping[str, np.ndarray],
    config: MapConfig | None,
    *,
    conditions: Iterable[Condition],
    seed: int,
    kinds: Sequence[str] = ("topview",),
    progress: bool = True,
    parallel: Parallel | None = None,
) -> dict[str, dict[tuple[Condition, str], Path]]:
    """`prepare` for several sequences ({sequence: frames}); returns {sequence: its files}.

    In parallel, the chunks of every sequence are queued at once, so the workers never wait for
    one sequence's last chunk before starting the next, and each sequence's files are written as
    soon as its chunks are in (an interrupted run keeps the sequences it finished)."""
    conds = list(dict.fromkeys(conditions))
    for kind in kinds:
        _check_kind(kind)
    if not source.cache_views:
        return {str(name): {} for name in frames}
    plans = [_plan(source, str(name), f, config, conds, seed, kinds) for name, f in frames.items()]
    todo = [plan for plan in plans if plan.missing]
    serially = parallel is None or parallel.serial
    whole = [p for p in todo if len(p.frames) < 2 or (serially and len(p.frames) <= CHUNK_FRAMES)]
    for plan in whole:
        views = render_views(source, plan.sequence, config, plan.frames, plan.offsets, plan.kinds,
                             progress=progress)
        for c, k in plan.missing:
            _save(plan.paths[c, k], views[c.name, k], plan.meta[c, k])
    chunked = [p for p in todo if p not in whole]
    if chunked:  # on the workers, or in this process for a pass longer than CHUNK_FRAMES
        _build_chunked(source, config, chunked, parallel or Parallel(), progress)
    return {plan.sequence: plan.paths for plan in plans}


def _build_chunk(
    source: DataSource, sequence: str, config: MapConfig | None, frames: np.ndarray,
    offsets: dict[str, np.ndarray | None], kinds: Sequence[str],
) -> dict[tuple[str, str], bytes]:
    """One chunk of `prepare`'s views, compressed (runs on a worker: the compression, as costly
    as the rendering, is spread over the workers, and only compressed bytes travel back)."""
    views = render_views(source, sequence, config, frames, offsets, kinds, progress=False)
    return {key: _compress(value) for key, value in views.items()}


#: The most frames one chunk of views holds. A longer pass (the long drive's 20 000 frames, a
#: 4 541-frame KITTI sequence at every frame) is rendered in chunks of at most this many, serially
#: as on workers, and each finished chunk is kept on disk (`_parts_dir`) until its pass is
#: complete, so an interrupted pass resumes from the chunks it finished. A chunk starts from a
#: fresh local map of the `window` scans before its first frame (`prepare`), so its views are the
#: serial ones, and reading those scans again costs `window` / `CHUNK_FRAMES` = 1 % more.
CHUNK_FRAMES = 1000


def _parts_dir(plan: _Plan) -> Path:
    """Where the finished chunks of `plan`'s pass wait: beside its first missing file, named
    after it (its key covers the source, frames, conditions and seed)."""
    first = plan.paths[plan.missing[0]]
    return first.with_name(first.stem + ".parts")


def _part_path(plan: _Plan, chunk: np.ndarray) -> Path:
    return _parts_dir(plan) / f"{int(chunk[0]):06d}-{int(chunk[-1]):06d}.zip"


def _keep_part(path: Path, chunk: dict[tuple[str, str], bytes]) -> None:
    """One finished chunk (its compressed views per (condition, kind)), written atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED, allowZip64=True) as archive:
            for (label, kind), data in chunk.items():
                archive.writestr(f"{label}/{kind}.npz", data)


def _kept_part(path: Path, needed: Sequence[tuple[str, str]]) -> dict[tuple[str, str], bytes] | None:
    """The chunk kept at `path` if it holds every (condition, kind) in `needed`, else None."""
    try:
        with zipfile.ZipFile(path) as archive:
            return {(label, kind): archive.read(f"{label}/{kind}.npz") for label, kind in needed}
    except (OSError, KeyError, zipfile.BadZipFile):
        return None


def _build_chunked(source: DataSource, config: MapConfig | None, plans: Sequence[_Plan], parallel: Parallel,
                   progress: bool) -> None:
    """Render the plans' views in chunks, on the workers or in this process (`CHUNK_FRAMES`),
    keeping each finished chunk on disk; write each plan's files (its compressed chunks, in frame
    order) once all its chunks are in, then drop the kept chunks."""
    import shutil

    from tqdm import tqdm

    if not plans:
        return
    portable = dataclasses.replace(source, _open={})  # open sequences stay in this process
    jobs: list[tuple[Any, ...]] = []
    owner: list[int] = []  # the plan of each job
    parts: list[Path] = []  # where each job's chunk is kept
    slot: list[int] = []  # each job's chunk, in frame order over all plans
    # each plan's finished chunks by their place in frame order: those an interrupted pass kept,
    # then those the jobs return
    chunks: dict[int, dict[int, Any]] = {p: {} for p in range(len(plans))}
    # chunks of about equal size over all sequences, a few per worker: enough to balance the
    # load, few enough that re-reading each chunk's first local map stays cheap
    size = max(1, -(-sum(len(plan.frames) for plan in plans) // (3 * parallel.slots())))
    size = CHUNK_FRAMES if parallel.serial else min(size, CHUNK_FRAMES)  # serially: to resume only
    index = 0
    for p, plan in enumerate(plans):
        n = len(plan.frames)
        needed = [(c.name, k) for c, k in plan.missing]
        for c in np.array_split(np.arange(n), -(-n // size)):
            if not len(c):
                continue
            part = _part_path(plan, c)
            earlier = _kept_part(part, needed) if part.is_file() else None
            if earlier is not None:
                chunks[p][index] = earlier
            else:
                offsets = {lb: None if o is None else o[c] for lb, o in plan.offsets.items()}
                jobs.append((portable, plan.sequence, config, plan.frames[c], offsets, plan.kinds))
                owner.append(p)
                parts.append(part)
                slot.append(index)
            index += 1
    waiting = [owner.count(p) for p in range(len(plans))]
    errors: dict[int, str] = {}
    names = ", ".join(plan.sequence for plan in plans)
    resumed = sum(len(c) for c in chunks.values())
    finished = [resumed]
    bar = tqdm(total=len(jobs) + resumed, initial=resumed, unit="chunk", disable=not progress,
               desc=f"maps {names} ({parallel.describe()})", leave=False)

    def finish(p: int) -> None:
        plan = plans[p]
        ordered = [chunks[p][j] for j in sorted(chunks[p])]
        for c, k in plan.missing:
            _save_parts(plan.paths[c, k], [chunk[c.name, k] for chunk in ordered], plan.meta[c, k])
        chunks[p].clear()
        shutil.rmtree(_parts_dir(plan), ignore_errors=True)

    def collect(i: int, result: JobResult) -> None:
        bar.update(1)
        finished[0] += 1
        report(f"maps {names}: {finished[0]} of {len(jobs) + resumed} chunks")
        p = owner[i]
        waiting[p] -= 1
        if result.error is not None:
            errors.setdefault(p, result.error)
            return
        if len(plans[p].frames) > CHUNK_FRAMES:  # a long pass: kept until it is complete
            _keep_part(parts[i], result.value)
        chunks[p][slot[i]] = result.value
        if waiting[p] == 0 and p not in errors:
            finish(p)

    for p in range(len(plans)):  # every chunk kept from an interrupted pass
        if waiting[p] == 0:
            finish(p)
    try:
        run_jobs(_build_chunk, jobs, parallel, on_done=collect)
    finally:
        bar.close()
    if errors:
        p, error = next(iter(sorted(errors.items())))
        where = "" if parallel.serial else " on a worker"
        raise DataError(f"building the maps of sequence {plans[p].sequence} failed{where}: {error}")


def load_views(
    source: DataSource,
    sequence: str,
    config: MapConfig | None,
    *,
    frames: np.ndarray,
    condition: Condition,
    seed: int,
    kind: str = "topview",
    progress: bool = True,
) -> np.ndarray | list[np.ndarray]:
    """Views of `sequence` at `frames` under `condition` (seeded offsets), from the cache or
    rendered and cached: (F, size, size) float32 in [0, 1] for "topview", or a list of F
    (M_i, 3) float32 viewpoint-frame point arrays for "points"."""
    _check_kind(kind)
    if not source.cache_views:
        n = len(source.sequence(sequence))
        frames = check_frames(frames, n, sequence)
        offsets = None if condition.is_clean else sample_offsets(len(frames), condition, seed)
        return render_views(source, sequence, config, frames, {condition.name: offsets}, [kind],
                                  progress=progress)[condition.name, kind]
    paths = prepare(source, sequence, config, frames=frames, conditions=[condition], seed=seed,
                    kinds=[kind], progress=progress)
    return _load(paths[condition, kind], kind)
