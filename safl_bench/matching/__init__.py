"""Stage 4, matching: descriptors' difference matrix -> matches.

`matcher` (the shared SeqSLAM matcher and the single-frame one), `settings` (the matcher
settings of an evaluation, `EvaluationConfig`), `presets` (named sets of those settings) and
`loop` (the plain-loop reference implementation the vectorised matcher is tested against).

``safl_bench.matching`` was the matcher module before the stages had folders: its names
(``from safl_bench.matching import match``) are still read and written through this package: they are `matcher`'s
(`safl_bench.common.oldmodule`, so that monkeypatching either path patches the same function).
"""

from __future__ import annotations

from safl_bench.common.oldmodule import stand_for

stand_for(__name__, f"{__name__}.matcher", ("matcher", "settings", "presets", "loop", "confidence"))
