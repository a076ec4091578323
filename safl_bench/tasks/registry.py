"""The task registry, modelled on Gymnasium's: `register`, `spec`, `make`, `registry`.

Ids are versioned (`SAFL/Synth00-T1R1-v0`). An id without its version resolves to the latest
registered version, with a warning naming it; an old version still resolves (old records stay
reproducible) with a warning naming the newer one. Unknown ids raise `RegistryError` with a
"did you mean" suggestion. Every task is also registered with Gymnasium (lazily: nothing is
loaded until `gymnasium.make`), so `gymnasium.make(task_id)` gives the streaming environment.
"""

from __future__ import annotations

import difflib
import warnings
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from safl_bench.errors import ConfigError, RegistryError
from safl_bench.tasks.spec import TaskSpec, make_id, parse_id

if TYPE_CHECKING:
    from safl_bench.sources import DataSource
    from safl_bench.tasks.task import Task

#: All registered tasks by id (read it; change it through `register` / `unregister`).
registry: dict[str, TaskSpec] = {}

#: Entry point of the Gymnasium environment registered for every task.
ENV_ENTRY_POINT = "safl_bench.tasks.env:TaskEnv"


def register(task: TaskSpec | str, *, gym: bool = True, **fields: Any) -> TaskSpec:
    """Register a task from a `TaskSpec` or from an id plus `TaskSpec` fields; return the spec.

    A second registration of the same id raises RegistryError: a changed definition needs a new
    version. With `gym=True` the id is registered with Gymnasium too.
    """
    spec_ = task if isinstance(task, TaskSpec) else TaskSpec(id=task, **fields)
    if isinstance(task, TaskSpec) and fields:
        spec_ = replace(task, **fields)
    if spec_.id in registry:
        raise RegistryError(
            f"task {spec_.id} is already registered; register a changed definition under a new version"
        )
    registry[spec_.id] = spec_
    if gym:
        import gymnasium

        gymnasium.register(id=spec_.id, entry_point=ENV_ENTRY_POINT, kwargs={"task_id": spec_.id})
    return spec_


def unregister(task_id: str) -> None:
    """Remove a task (and its Gymnasium registration); meant for tests and temporary tasks."""
    if registry.pop(task_id, None) is None:
        raise RegistryError(f"task {task_id} is not registered")
    import gymnasium

    gymnasium.registry.pop(task_id, None)


def _versions(namespace: str | None, name: str) -> list[int]:
    return sorted(
        s.version for s in registry.values() if s.namespace == namespace and s.name == name
    )


def _unknown(task_id: str) -> RegistryError:
    ids = sorted(registry)
    names = sorted({make_id(s.namespace, s.name, None) for s in registry.values()})
    close = difflib.get_close_matches(task_id, ids + names, n=3, cutoff=0.6)
    hint = (
        f" Did you mean: {', '.join(close)}?"
        if close
        else " Run `safl-bench list tasks` to see them."
    )
    return RegistryError(f"unknown task {task_id!r}.{hint}")


def spec(task_id: str) -> TaskSpec:
    """The spec of `task_id`; an id without version picks the latest version (with a warning)."""
    if task_id in registry:
        found = registry[task_id]
        latest = _versions(found.namespace, found.name)[-1]
        if latest > found.version:
            warnings.warn(
                f"task {task_id} is superseded by {make_id(found.namespace, found.name, latest)}",
                stacklevel=2,
            )
        return found
    try:
        namespace, name, version = parse_id(task_id)
    except ConfigError:
        raise _unknown(task_id) from None
    versions = _versions(namespace, name)
    if not versions:
        raise _unknown(task_id)
    if version is None:
        chosen = make_id(namespace, name, versions[-1])
        warnings.warn(f"using the latest version {chosen} for {task_id}", stacklevel=2)
        return registry[chosen]
    listed = ", ".join(f"v{v}" for v in versions)
    raise RegistryError(f"task {task_id} has no version v{version}; registered versions: {listed}")


def make(
    task_id: str,
    *,
    kitti_root: str | None = None,
    bev_root: str | None = None,
    bev_resolution_m: float | None = None,
    source: DataSource | None = None,
    progress: bool = True,
) -> Task:
    """Materialise a task: open its data source and sequence, select frames, build ground truth.

    Views (top-view maps or points) are rendered or read from the map cache on first access
    (`task.database(kind)`, `task.queries(kind)`, or all at once with `task.prepare(...)`).
    `source` overrides the source the spec names (it must be of the same kind); otherwise KITTI
    tasks take `kitti_root` or $SAFL_KITTI_ROOT, top-view image tasks `bev_root` or
    $SAFL_BEV_ROOT (at `bev_resolution_m` metres per pixel, default 0.4) and synthetic tasks the
    embedded default.
    """
    from safl_bench.tasks.task import Task

    return Task.from_spec(spec(task_id), kitti_root=kitti_root, bev_root=bev_root,
                          bev_resolution_m=bev_resolution_m, source=source, progress=progress)
