"""The task registry, modelled on Gymnasium's: `register`, `spec`, `registry` (and `make`, in
`safl_bench.tasks.task` beside the `Task` it builds, so that the two modules do not import each
other; `safl_bench.tasks.make` is the one users call).

Ids are versioned (`SAFL/Synth00-T1R1-v4`). An id without its version resolves to the latest
registered version, with a warning naming it; an old version still resolves (old records stay
readable) with a warning naming the newer one. A synthetic task defined on other synthetic data
than this safl-bench generates resolves too, but `make` (and a run) refuses it in one line
naming the task to run instead (`check_data_version`). Unknown ids raise `RegistryError` with a
"did you mean" suggestion. Every task is also registered with Gymnasium (lazily: nothing is
loaded until `gymnasium.make`), so `gymnasium.make(task_id)` gives the streaming environment.
"""

from __future__ import annotations

import difflib
import warnings
from dataclasses import replace
from typing import Any

from safl_bench.errors import ConfigError, RegistryError
from safl_bench.tasks.spec import (
    TaskSpec,
    current_synth_data_version,
    generated_synth_data_versions,
    make_id,
    parse_id,
)

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


#: Task ids `spec` has warned about in this process (each warning is printed once).
_WARNED: set[str] = set()


def spec(task_id: str) -> TaskSpec:
    """The spec of `task_id`; an id without version picks the latest version (with a warning)."""
    if task_id in registry:
        found = registry[task_id]
        latest = _versions(found.namespace, found.name)[-1]
        if latest > found.version and task_id not in _WARNED:
            _WARNED.add(task_id)  # once per task and process, whichever caller asks first
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
        if task_id not in _WARNED:
            _WARNED.add(task_id)
            warnings.warn(f"using the latest version {chosen} for {task_id}", stacklevel=2)
        return registry[chosen]
    listed = ", ".join(f"v{v}" for v in versions)
    raise RegistryError(f"task {task_id} has no version v{version}; registered versions: {listed}")


def latest_on_data(spec_: TaskSpec, data_version: str) -> str | None:
    """The id of the highest registered version of `spec_`'s task name defined on synthetic
    `data_version`; None when there is none."""
    versions = [s.version for s in registry.values() if s.namespace == spec_.namespace
                and s.name == spec_.name and s.data_version == data_version]
    return make_id(spec_.namespace, spec_.name, max(versions)) if versions else None


def check_data_version(spec_: TaskSpec) -> None:
    """Raise ConfigError when `spec_` is a synthetic task defined on a version of the synthetic
    data that this safl-bench no longer generates: its data cannot be made any more, so it may be
    looked up (its records resolve) but not materialised or run. The message names the
    registered version of the task on the newest data."""
    if spec_.source != "synth" or spec_.data_version in generated_synth_data_versions():
        return
    current = current_synth_data_version()
    newest = latest_on_data(spec_, current)
    instead = (f"run {newest}" if newest is not None
               else f"register the task under a new version on data version {current}")
    made = ", ".join(generated_synth_data_versions())
    raise ConfigError(
        f"{spec_.id} was defined on synthetic data version {spec_.data_version}; this safl-bench "
        f"generates versions {made}: {instead} (or, for the old data, a safl-bench that "
        f"generates version {spec_.data_version})"
    )


def runnable_spec(task_id: str) -> TaskSpec:
    """`spec(task_id)` of a task about to be materialised or run: `check_data_version` first,
    so that an old synthetic task fails in one line (before `spec` warns that it is superseded)."""
    if task_id in registry:
        check_data_version(registry[task_id])
    found = spec(task_id)
    check_data_version(found)
    return found
