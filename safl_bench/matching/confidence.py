"""The one orientation rule between the matcher and the metrics.

A matcher's score is lower = better (+inf = no match reported); the metrics rank by confidence,
higher = better. `confidence_from_score` is the conversion both sides use (the matcher's
`MatchResult.confidence`, the metrics' readers of recorded scores), kept apart from the matcher
so that the metrics do not import its kernels.
"""

from __future__ import annotations

import numpy as np


def confidence_from_score(score: np.ndarray) -> np.ndarray:
    """Matcher score (lower = better, +inf = no match) -> confidence (higher = better)."""
    return -np.asarray(score, dtype=np.float64)
