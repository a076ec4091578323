"""A stage package that stands for the module of the same name it replaced.

Before the stages had folders, ``safl_bench.matching`` and ``safl_bench.evaluation`` were
modules; now they are the packages of their stages, and their old contents live in
`safl_bench.matching.matcher` and `safl_bench.evaluation.cell`. `stand_for` makes such a
package read AND write the old module's names in that module: ``from safl_bench.matching
import match`` works, and ``monkeypatch.setattr(safl_bench.evaluation, "describe", f)`` replaces
the function that the evaluation calls (a plain re-export would patch only the package's copy),
and deleting such a name again (how pytest undoes it) gives the module its own value back.
The module is imported on first use, so importing the package costs nothing.
"""

from __future__ import annotations

import importlib
import sys
from types import ModuleType
from typing import Any


class _StandsFor(ModuleType):
    """A package whose unknown names are those of one of its modules (`_stands_for`)."""

    def _target(self) -> ModuleType:
        return importlib.import_module(self.__dict__["_stands_for"])

    def __getattr__(self, name: str) -> Any:
        # only reached when the package itself has no such name
        if name.startswith("__") or name in self.__dict__["_own_modules"]:
            raise AttributeError(f"module {self.__name__!r} has no attribute {name!r}")
        try:
            return getattr(self._target(), name)
        except AttributeError:
            raise AttributeError(f"module {self.__name__!r} has no attribute {name!r}") from None

    def __setattr__(self, name: str, value: Any) -> None:
        # the import system sets submodules and dunders on the package: those stay here
        if name.startswith("__") or isinstance(value, ModuleType) or name in self.__dict__:
            super().__setattr__(name, value)
            return
        target = self._target()
        replaced = self.__dict__["_replaced"]
        if name not in replaced:  # what deleting the package's name will restore
            replaced[name] = getattr(target, name, _MISSING)
        setattr(target, name, value)

    def __delattr__(self, name: str) -> None:
        # the name was never the package's own (pytest's monkeypatch undoes a patch of a name
        # that is not in the package's __dict__ by deleting it): give the module its own back
        if name in self.__dict__:
            super().__delattr__(name)
            return
        replaced = self.__dict__["_replaced"]
        if name not in replaced:
            raise AttributeError(f"module {self.__name__!r} has no attribute {name!r} of its own")
        original = replaced.pop(name)
        if original is _MISSING:
            delattr(self._target(), name)
        else:
            setattr(self._target(), name, original)


_MISSING = object()


def stand_for(package: str, module: str, own_modules: tuple[str, ...]) -> None:
    """Make `package` (already in sys.modules: call it from its __init__) read and write the
    names of `module`; `own_modules` are the package's modules, never looked up there (importing
    them goes on as usual)."""
    pkg = sys.modules[package]
    pkg.__dict__["_stands_for"] = module
    pkg.__dict__["_own_modules"] = frozenset(own_modules)
    pkg.__dict__["_replaced"] = {}
    pkg.__class__ = _StandsFor
