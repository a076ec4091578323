"""`Task`: a materialised task: its frames, positions, times, ground truth and views.

Views are what methods read, by kind: "topview" (F, H, W) float32 maps in [0, 1], or "points"
(a list of (M_i, 3) float32 local-map points in the viewpoint frame). They come from the map
cache on first access, so making a task is cheap until a view is asked for:

    task = safl_bench.tasks.make("SAFL/Synth00-T5R1.5-v4")
    db = task.database("topview")      # clean maps of every `step`-th frame
    q = task.queries("topview")        # the same frames re-rendered with viewpoint noise
    labels = task.truth.labels(match)  # per query: TP 1, FP -1, excluded 0

Ground-truth positions of a query are those of its frame (`KittiSequence.positions`): the
viewpoint noise simulates a different pass over the same place; it does not move the place.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from safl_bench.errors import ConfigError, DataError
from safl_bench.evaluation.groundtruth import GroundTruth
from safl_bench.tasks.registry import check_data_version, runnable_spec
from safl_bench.tasks.spec import TaskSpec
from safl_bench.views.mapbuild import select_frames
from safl_bench.views.noise import CLEAN, sample_offsets

if TYPE_CHECKING:
    from safl_bench.common.parallel import Parallel
    from safl_bench.matching.settings import EvaluationConfig
    from safl_bench.sources import DataSource

KINDS = ("topview", "points")


class Task:
    """One task ready to run: database and query frames with ground truth; views on demand.

    Attributes: `spec`, `source` (None for a task built from arrays), `database_frames` and
    `query_frames` (indices into the sequence: every `step`-th frame for both, or the spec's
    frame ranges), `database_positions` / `query_positions`
    (n, 2) m, `database_times` / `query_times` (n,) s, `query_offsets` (Nq, 3) the viewpoint
    noise [dx, dy, dtheta] each query was rendered with, `truth` (`GroundTruth`),
    `query_source` (the source of the queries where it is not `source`: the second image folder
    of a task whose queries are rotated, `TaskSpec.rotated`; None otherwise).
    """

    def __init__(
        self,
        spec: TaskSpec,
        *,
        positions: np.ndarray,
        times: np.ndarray,
        source: DataSource | None = None,
        progress: bool = True,
        headings: np.ndarray | None = None,
        query_source: DataSource | None = None,
    ) -> None:
        positions = np.asarray(positions, dtype=np.float64)
        times = np.asarray(times, dtype=np.float64)
        if positions.ndim != 2 or positions.shape[1] != 2 or len(times) != len(positions):
            raise DataError(
                f"task {spec.id}: need (n, 2) positions and n times, got {positions.shape}, {times.shape}"
            )
        self.spec = spec
        self.source = source
        self.query_source = query_source
        self.progress = progress
        self.sequence_length = len(positions)
        self.database_frames = self._frames(spec.database_frames)
        self.query_frames = self._frames(spec.query_frames)
        self.database_positions = positions[self.database_frames]
        self.query_positions = positions[self.query_frames]
        self.database_times = times[self.database_frames]
        self.query_times = times[self.query_frames]
        self.query_offsets = sample_offsets(len(self.query_frames), spec.condition, spec.seed)
        #: (Nq,) heading of each query frame (rad), where the source has poses; None otherwise
        self.query_headings = (None if headings is None
                               else np.asarray(headings, dtype=np.float64)[self.query_frames])
        self._viewpoint_truth: GroundTruth | None = None
        self.truth = GroundTruth(
            query_positions=self.query_positions,
            database_positions=self.database_positions,
            query_times=self.query_times,
            database_times=self.database_times,
            tp_radius=spec.tp_radius_m,
            fp_radius=spec.fp_radius_m,
            window_s=spec.window_s if spec.protocol == "revisit" else None,
        )
        self._views: dict[tuple[str, str], Any] = {}

    def _frames(self, frame_range: tuple[int, int] | None) -> np.ndarray:
        """Every `step`-th frame of the sequence, or of `frame_range` [start, stop)."""
        if frame_range is None:
            return select_frames(self.sequence_length, self.spec.step)
        start, stop = frame_range
        if stop > self.sequence_length:
            raise DataError(f"task {self.spec.id}: frames {start}..{stop - 1} asked for, but sequence "
                            f"{self.spec.sequence} has {self.sequence_length} frames")
        return np.arange(start, stop, self.spec.step, dtype=np.int64)

    @property
    def shared_views(self) -> bool:
        """Whether the queries are the database views themselves (same frames, clean, same source)."""
        if self.query_source is not None:
            return False
        return self.spec.protocol == "revisit" or (
            self.spec.condition.is_clean and self.spec.query_frames is None)

    @classmethod
    def from_spec(
        cls,
        spec: TaskSpec,
        *,
        kitti_root: str | None = None,
        bev_root: str | None = None,
        bev_resolution_m: float | None = None,
        source: DataSource | None = None,
        progress: bool = True,
        bev_rot_root: str | None = None,
    ) -> Task:
        """Open the spec's data source and sequence (or `source`, of the same kind), and the
        second image folder of a task whose queries are rotated (`bev_rot_root`, else
        $SAFL_BEV_ROT_ROOT); a synthetic task on other synthetic data than this safl-bench
        generates is a ConfigError."""
        from safl_bench.sources import DEFAULT_RESOLUTION_M, open_query_source, open_source

        check_data_version(spec)
        resolution = bev_resolution_m or DEFAULT_RESOLUTION_M
        if source is None:
            source = open_source(spec, kitti_root=kitti_root, bev_root=bev_root, progress=progress,
                                 bev_resolution_m=resolution, bev_rot_root=bev_rot_root)
        elif source.kind != spec.source:
            raise ConfigError(
                f"task {spec.id} runs on {spec.source} data, got a {source.kind} source"
            )
        try:
            sequence = source.sequence(spec.sequence)
            positions, times = sequence.positions, sequence.times
            headings = getattr(sequence, "headings", None)
            query_source = open_query_source(spec, source, bev_rot_root=bev_rot_root,
                                             bev_resolution_m=resolution)
        except DataError as exc:
            message = str(exc)
            raise DataError(message if message.startswith(f"task {spec.id}") else
                            f"task {spec.id}: {message}") from None
        return cls(spec, positions=positions, times=times, source=source, progress=progress,
                   headings=headings, query_source=query_source)

    @classmethod
    def from_arrays(
        cls,
        spec: TaskSpec,
        *,
        positions: np.ndarray,
        times: np.ndarray,
        database: Any,
        queries: Any,
        kind: str = "topview",
    ) -> Task:
        """A task on in-memory data: views of the selected frames given for one `kind`."""
        task = cls(spec, positions=positions, times=times, progress=False)
        for role, views, frames in (("database", database, task.database_frames),
                                    ("queries", queries, task.query_frames)):
            if len(views) != len(frames):
                raise DataError(f"task {spec.id}: {len(views)} {role} views for {len(frames)} frames")
            task._views[role, kind] = views
        return task

    def truth_for(self, evaluation: EvaluationConfig) -> GroundTruth:
        """The ground truth an evaluation scores against (`EvaluationConfig.truth_at`):
        ``frame``, `truth` (true places within the radius of each query frame's pose);
        ``viewpoint``, the same with each query placed at the noisy viewpoint its view was made
        at (the frame's pose moved by its `query_offsets` in the robot frame, as
        `views.topview.noisy_viewpoints` moves the renderer). A noisy query whose view shows the
        place 15 m ahead has its true places there, not at its frame. Which one the authors
        scored with is not in their code (`matching.presets`' citation of ``truth_at``)."""
        if evaluation.truth_at == "frame" or not self.query_offsets[:, :2].any():
            return self.truth
        if self.query_headings is None:
            raise ConfigError(f"task {self.id}: truth_at=viewpoint needs the frames' headings, "
                              "which this task's data does not have (a task built from arrays)")
        if self._viewpoint_truth is None:
            from safl_bench.views.topview import noisy_viewpoints

            frames = np.column_stack([self.query_positions, self.query_headings])
            moved = noisy_viewpoints(frames, self.query_offsets)[:, :2]
            self._viewpoint_truth = dataclasses.replace(self.truth, query_positions=moved)
        return self._viewpoint_truth

    @property
    def id(self) -> str:
        return self.spec.id

    def __len__(self) -> int:
        """Number of queries."""
        return len(self.query_frames)

    def __repr__(self) -> str:
        return (
            f"Task({self.spec.id}: {len(self.database_frames)} database frames, "
            f"{len(self.query_frames)} queries, protocol {self.spec.protocol})"
        )

    def database(self, kind: str = "topview") -> Any:
        """Database views: (Ndb, H, W) float32 top views, or a list of (M_i, 3) point arrays."""
        return self._load("database", kind)

    def queries(self, kind: str = "topview") -> Any:
        """Query views, same kinds as `database`; revisit tasks query with the database views."""
        return self._load("queries", kind)

    def prepare(self, kinds: Sequence[str] = ("topview",)) -> None:
        """Render every view the task needs in one pass over the scans (then cached on disk)."""
        from safl_bench.views import mapcache

        for kind in kinds:
            self._check_kind(kind)
        if self.source is None:
            return
        for kind in kinds:
            self.source.check_kind(kind)
            if self.query_source is not None:  # an image folder: its views are never cached
                self.query_source.check_kind(kind)
        mapcache.prepare(
            self.source,
            self.spec.sequence,
            self.spec.map_config,
            frames=self.database_frames,
            conditions=self._conditions(),
            seed=self.spec.seed,
            kinds=tuple(kinds),
            progress=self.progress,
        )

    def _conditions(self) -> list:
        """The conditions rendered at the database frames (queries on other frames: their own)."""
        if self.spec.protocol == "revisit" or self.spec.condition.is_clean:
            return [CLEAN]
        return [CLEAN, self.spec.condition]

    @staticmethod
    def _check_kind(kind: str) -> None:
        if kind not in KINDS:
            raise ConfigError(f"unknown view kind {kind!r}; kinds: {', '.join(KINDS)}")

    def _load(self, role: str, kind: str) -> Any:
        self._check_kind(kind)
        if role == "queries" and self.shared_views and (role, kind) not in self._views:
            return self._load("database", kind)  # same frames, same (clean) rendering
        if (role, kind) not in self._views:
            if self.source is None:
                raise DataError(f"task {self.spec.id} was built from arrays without {kind} views")
            from safl_bench.views import mapcache

            self.prepare([kind])  # database and queries in one pass over the scans
            condition = CLEAN if role == "database" else self.spec.condition
            frames = self.database_frames if role == "database" else self.query_frames
            source = self.query_source if role == "queries" and self.query_source else self.source
            self._views[role, kind] = mapcache.load_views(
                source,
                self.spec.sequence,
                self.spec.map_config,
                frames=frames,
                condition=condition,
                seed=self.spec.seed,
                kind=kind,
                progress=self.progress,
            )
        return self._views[role, kind]

    def info(self) -> dict[str, Any]:
        """What a result record stores about the task: the spec, its fingerprint, the data."""
        out: dict[str, Any] = self.spec.to_dict()
        out["n_database"] = len(self.database_frames)
        out["n_queries"] = len(self.query_frames)
        if self.source is not None:
            out["data_label"] = self.source.label
            out["data_fingerprint"] = self.source.fingerprint(self.spec.sequence)
            notes = self.source.notes(self.spec.sequence)
            if self.query_source is not None:  # both folders' files, and which views each gave
                from safl_bench.common.fingerprint import fingerprint

                out["data_fingerprint"] = fingerprint(
                    out["data_fingerprint"], self.query_source.fingerprint(self.spec.sequence))
                notes = [f"database {n}" for n in notes] + [
                    f"queries {n}" for n in self.query_source.notes(self.spec.sequence)]
            if notes:
                out["data_notes"] = notes
        return out


def prepare_tasks(tasks: Sequence[Task], kinds: Sequence[str] = ("topview",), *,
                  parallel: Parallel | None = None, progress: bool = True) -> dict[int, str]:
    """Render the views of many tasks with as few passes over the scans as possible: tasks on
    the same sequence, frames, map configuration and seed (e.g. the paper's twelve conditions)
    share one pass for all their conditions, instead of one pass each; with `parallel`, each
    pass runs in chunks on the workers (`mapcache.prepare`). Returns {index in `tasks`: why its
    views could not be rendered}; the other tasks' views are cached."""
    from safl_bench.errors import SaflError
    from safl_bench.views import mapcache

    groups: dict[tuple[Any, ...], tuple[DataSource, Task, list[Any], list[int]]] = {}
    failed: dict[int, str] = {}
    for i, task in enumerate(tasks):
        if task.source is None:
            continue
        for kind in kinds:
            task._check_kind(kind)
            try:
                task.source.check_kind(kind)
            except SaflError as exc:
                failed[i] = str(exc)
                continue
            key = (task.source.kind, str(task.source.root), task.spec.sequence, task.spec.map_config,
                   task.database_frames.tobytes(), task.spec.seed, kind)
            _, _, conditions, members = groups.setdefault(key, (task.source, task, [], []))
            conditions.extend(c for c in task._conditions() if c not in conditions)
            members.append(i)
    for (*_, kind), (source, task, conditions, members) in groups.items():
        try:
            mapcache.prepare(source, task.spec.sequence, task.spec.map_config,
                             frames=task.database_frames, conditions=conditions, seed=task.spec.seed,
                             kinds=(kind,), progress=progress, parallel=parallel)
        except SaflError as exc:
            failed.update((i, str(exc)) for i in members)
    return failed


def make(
    task_id: str,
    *,
    kitti_root: str | None = None,
    bev_root: str | None = None,
    bev_resolution_m: float | None = None,
    source: DataSource | None = None,
    progress: bool = True,
    bev_rot_root: str | None = None,
) -> Task:
    """Materialise a task: open its data source and sequence, select frames, build ground truth.

    Views (top-view maps or points) are rendered or read from the map cache on first access
    (`task.database(kind)`, `task.queries(kind)`, or all at once with `task.prepare(...)`).
    `source` overrides the source the spec names (it must be of the same kind); otherwise KITTI
    tasks take `kitti_root` or $SAFL_KITTI_ROOT, top-view image tasks `bev_root` or
    $SAFL_BEV_ROOT (at `bev_resolution_m` metres per pixel, default 0.4; their rotated tasks also
    `bev_rot_root` or $SAFL_BEV_ROT_ROOT, `TaskSpec.rotated`) and synthetic tasks the embedded
    default. A synthetic task on other synthetic data than this safl-bench generates
    raises ConfigError (`check_data_version`).
    """
    return Task.from_spec(runnable_spec(task_id), kitti_root=kitti_root, bev_root=bev_root,
                          bev_resolution_m=bev_resolution_m, source=source, progress=progress,
                          bev_rot_root=bev_rot_root)
