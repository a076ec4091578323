"""safl-bench: a Gymnasium-style benchmark for LiDAR loop-closure-detection descriptors.

The package holds one folder per stage, in the order data flows (docs/architecture.md):
`sources` -> `views` -> `methods` -> `matching` -> `evaluation` -> `tasks` -> `results` ->
`run` -> `leaderboard`, with `common` (what every stage needs), `synth` (the synthetic world),
`analysis`, `bench` (every benchmark) and `cli`. At the top stay only this face, `errors` and
`paths`.

The names a plug-in and a script need are on the face, imported on first use (so that
`import safl_bench` loads neither torch nor the stages): ``from safl_bench import Method,
as_topview, register_method, make_method, check_method, load_record, load_records``.

The modules that lived at the top before (``safl_bench.metrics``, ``safl_bench.method_registry``
...) still import under their old names: `MOVED_MODULES` maps each to its new path and an
import finder hands back the very module object of the new path, so code, plug-ins and
``monkeypatch.setattr("safl_bench.runner.X", ...)`` that name the old path see the same module.
(``safl_bench.matching`` and ``safl_bench.evaluation`` are now the packages of their stages; they
resolve the names of their old modules themselves.)
"""

from __future__ import annotations

import importlib
import importlib.machinery
import sys
from types import ModuleType
from typing import TYPE_CHECKING, Any, cast

if TYPE_CHECKING:
    from importlib.abc import Loader

    from safl_bench.methods.check import check_method
    from safl_bench.methods.method import Method, as_topview, make_method, register_method
    from safl_bench.results.records import load_record, load_records

__version__ = "0.1.0"

#: Old module path -> new module path (issue #27's move to one folder per stage).
MOVED_MODULES: dict[str, str] = {
    "safl_bench.atomic": "safl_bench.common.atomic",
    "safl_bench.fingerprint": "safl_bench.common.fingerprint",
    "safl_bench.parallel": "safl_bench.common.parallel",
    "safl_bench.localmap": "safl_bench.views.localmap",
    "safl_bench.topview": "safl_bench.views.topview",
    "safl_bench.bevdensity": "safl_bench.views.bevdensity",
    "safl_bench.resample": "safl_bench.views.resample",
    "safl_bench.mapbuild": "safl_bench.views.mapbuild",
    "safl_bench.mapcache": "safl_bench.views.mapcache",
    "safl_bench.mapconfig": "safl_bench.views.mapconfig",
    "safl_bench.noise": "safl_bench.views.noise",
    "safl_bench.method": "safl_bench.methods.method",
    "safl_bench.method_registry": "safl_bench.methods.method",
    "safl_bench.check": "safl_bench.methods.check",
    "safl_bench.weights": "safl_bench.methods.weights",
    "safl_bench.descriptor_cache": "safl_bench.methods.descriptor_cache",
    "safl_bench.training": "safl_bench.methods.training",
    "safl_bench.training_data": "safl_bench.methods.training_data",
    "safl_bench.distance": "safl_bench.methods.distance",
    "safl_bench.matcher_presets": "safl_bench.matching.presets",
    "safl_bench.matching_loop": "safl_bench.matching.loop",
    "safl_bench.groundtruth": "safl_bench.evaluation.groundtruth",
    "safl_bench.metrics": "safl_bench.evaluation.metrics",
    "safl_bench.uncertainty": "safl_bench.evaluation.uncertainty",
    "safl_bench.records": "safl_bench.results.records",
    "safl_bench.provenance": "safl_bench.results.provenance",
    "safl_bench.runner": "safl_bench.run.runner",
    "safl_bench.timing": "safl_bench.run.timing",
    "safl_bench.matching_bench": "safl_bench.bench.matching_bench",
    "safl_bench.method_bench": "safl_bench.bench.method_bench",
    "safl_bench.source_bench": "safl_bench.bench.source_bench",
    "safl_bench.parallel_bench": "safl_bench.bench.parallel_bench",
    "safl_bench.seeds_bench": "safl_bench.bench.seeds_bench",
    "safl_bench.explain": "safl_bench.analysis.explain",
    "safl_bench.fidelity": "safl_bench.analysis.fidelity",
}


class _MovedModuleFinder:
    """Imports an old module path as the module of its new path (the same object): a meta-path
    finder and its loader (plain methods: importing `importlib.abc` would cost more than this)."""

    def find_spec(self, fullname: str, path: object = None,
                  target: object = None) -> importlib.machinery.ModuleSpec | None:
        if fullname not in MOVED_MODULES:
            return None
        return importlib.machinery.ModuleSpec(fullname, cast("Loader", self))

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        module = importlib.import_module(MOVED_MODULES[spec.name])
        self._own_spec = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        # the import system stamped the old path's spec on the module: give it back its own
        module.__spec__ = self._own_spec

if not any(isinstance(f, _MovedModuleFinder) for f in sys.meta_path):
    sys.meta_path.insert(0, _MovedModuleFinder())

# Register the built-in tasks (with Gymnasium too, lazily: nothing is loaded until a task is made),
# so that `gymnasium.make("SAFL/Synth00-T1R1-v4")` works after `import safl_bench`.
from safl_bench import tasks as _tasks  # noqa: E402, F401

#: The package face: name -> the module that defines it (imported on first use).
_FACE = {
    "Method": "safl_bench.methods.method",
    "as_topview": "safl_bench.methods.method",
    "register_method": "safl_bench.methods.method",
    "make_method": "safl_bench.methods.method",
    "check_method": "safl_bench.methods.check",
    "load_record": "safl_bench.results.records",
    "load_records": "safl_bench.results.records",
}

__all__ = ["MOVED_MODULES", "Method", "__version__", "as_topview", "check_method", "load_record",
           "load_records", "make_method", "register_method"]


def __getattr__(name: str) -> Any:
    if name in _FACE:
        return getattr(importlib.import_module(_FACE[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
