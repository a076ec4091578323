"""Stage 5, evaluation: what a method's matches score.

`groundtruth` (which database frames are a query's true places), `metrics` (the measures and
their curves), `uncertainty` (intervals over seeds and queries, paired differences) and `cell`
(the evaluation of one method on one task: descriptors -> difference matrix -> matches ->
metrics).

``safl_bench.evaluation`` was the one-cell module before the stages had folders: its names
(``from safl_bench.evaluation import evaluate``) still resolve here, lazily, to `cell`'s.
"""

from __future__ import annotations

import importlib
from typing import Any

#: This package's modules: never looked up in `cell` (importing them goes on as usual).
_MODULES = ('cell', 'groundtruth', 'metrics', 'uncertainty')


def __getattr__(name: str) -> Any:
    if name.startswith("__") or name in _MODULES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module = importlib.import_module(f"{__name__}.cell")
    try:
        return getattr(module, name)
    except AttributeError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
