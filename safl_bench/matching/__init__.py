"""Stage 4, matching: descriptors' difference matrix -> matches.

`matcher` (the shared SeqSLAM matcher and the single-frame one), `settings` (the matcher
settings of an evaluation, `EvaluationConfig`), `presets` (named sets of those settings) and
`loop` (the plain-loop reference implementation the vectorised matcher is tested against).

``safl_bench.matching`` was the matcher module before the stages had folders: its names
(``from safl_bench.matching import match``) still resolve here, lazily, to `matcher`'s.
"""

from __future__ import annotations

import importlib
from typing import Any

#: This package's modules: never looked up in `matcher` (importing them goes on as usual).
_MODULES = ('matcher', 'settings', 'presets', 'loop', 'confidence')


def __getattr__(name: str) -> Any:
    if name.startswith("__") or name in _MODULES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module = importlib.import_module(f"{__name__}.matcher")
    try:
        return getattr(module, name)
    except AttributeError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
