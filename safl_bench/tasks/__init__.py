"""Benchmark tasks: versioned specs, a Gymnasium-style registry, materialised tasks, and the
streaming environment (`gymnasium.make(task_id)` after `import safl_bench`).

    from safl_bench import tasks
    task = tasks.make("SAFL/Synth00-T5R1.5-v4")
    db, q = task.database("topview"), task.queries("topview")
    labels = task.truth.labels(matches)          # TP 1 / FP -1 / excluded 0
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from safl_bench.tasks.builtin import SUITES, register_builtin, suite
from safl_bench.tasks.registry import register, registry, spec, unregister
from safl_bench.tasks.spec import TaskSpec

if TYPE_CHECKING:
    from safl_bench.tasks.task import make

register_builtin()

__all__ = ["SUITES", "TaskSpec", "make", "register", "registry", "spec", "suite", "unregister"]


def __getattr__(name: str) -> Any:
    # `make` lives beside the Task it builds; importing it on first use keeps `import safl_bench`
    # from loading the ground truth and the views (registering the tasks needs neither)
    if name == "make":
        from safl_bench.tasks.task import make

        return make
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
