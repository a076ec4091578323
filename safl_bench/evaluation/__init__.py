"""Stage 5, evaluation: what a method's matches score.

`groundtruth` (which database frames are a query's true places), `metrics` (the measures and
their curves), `uncertainty` (intervals over seeds and queries, paired differences) and `cell`
(the evaluation of one method on one task: descriptors -> difference matrix -> matches ->
metrics).

``safl_bench.evaluation`` was the one-cell module before the stages had folders: its names
(``from safl_bench.evaluation import evaluate``) still resolve here, lazily, to `cell`'s.
"""

from __future__ import annotations

from typing import Any


def __getattr__(name: str) -> Any:
    from safl_bench.evaluation import cell

    try:
        return getattr(cell, name)
    except AttributeError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
