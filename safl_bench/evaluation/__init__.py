"""Stage 5, evaluation: what a method's matches score.

`groundtruth` (which database frames are a query's true places), `metrics` (the measures and
their curves), `uncertainty` (intervals over seeds and queries, paired differences) and `cell`
(the evaluation of one method on one task: descriptors -> difference matrix -> matches ->
metrics).

``safl_bench.evaluation`` was the one-cell module before the stages had folders: its names
(``from safl_bench.evaluation import evaluate``) are still read and written through this package: they are `cell`'s
(`safl_bench.common.oldmodule`, so that monkeypatching either path patches the same function).
"""

from __future__ import annotations

from safl_bench.common.oldmodule import stand_for

stand_for(__name__, f"{__name__}.cell", ("cell", "groundtruth", "metrics", "uncertainty"))
