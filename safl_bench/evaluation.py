"""Evaluation of one method on one task: descriptors → difference matrix → matches → metrics.

This is the batch evaluation that every result record comes from. Both matching modes run on
the same difference matrix: the shared SeqSLAM matcher ("sequence") and the nearest database
frame ("single_frame"), so a reader sees what the sequence search adds. Revisit tasks restrict
each query to the database frames it may match (`GroundTruth.db_limit`). Single-frame results
also carry Recall@N (`RECALL_AT`), the retrieval literature's measure, from the same matrix.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from safl_bench.errors import DataError
from safl_bench.groundtruth import EXCLUDED, TP, GroundTruth
from safl_bench.matching import MatcherConfig, MatchResult, match
from safl_bench.method import Method
from safl_bench.metrics import Metrics, evaluate, retrieval_recall

#: The matching modes every evaluation reports, in the order tables show them.
MODES = ("sequence", "single_frame")
#: The N of the Recall@N that single-frame results report.
RECALL_AT = (1, 5, 10)


@dataclass(frozen=True)
class EvaluationConfig:
    """The matcher settings of an evaluation (recorded with every result)."""

    sequence: MatcherConfig = field(default_factory=MatcherConfig)

    @property
    def single_frame(self) -> MatcherConfig:
        """The no-sequence baseline (`matching.single_frame`'s settings: one frame, no contrast
        enhancement), scored like the sequence matcher."""
        seq = self.sequence
        return MatcherConfig(method="single_frame", ds=0, enhance_window=0, score=seq.score,
                             ratio_window=seq.ratio_window, dtype=seq.dtype)

    def matcher(self, mode: str) -> MatcherConfig:
        return self.sequence if mode == "sequence" else self.single_frame

    def to_dict(self) -> dict[str, Any]:
        return {mode: self.matcher(mode).to_dict() for mode in MODES}


@dataclass
class Evaluation:
    """What one evaluation produced: matches and metrics per mode, and how long each stage took."""

    matches: dict[str, MatchResult]
    metrics: dict[str, Metrics]
    describe_s: float  # both sides, all frames, in the method's own batching
    n_described: int
    matcher_s: float  # the sequence matcher on the difference matrix


def score_matches(truth: GroundTruth, result: MatchResult) -> Metrics:
    """Metrics of one matcher's answers against the task's ground truth.

    A query answered with a frame in the excluded band (revisit protocol) is left out; a query
    the matcher could not answer (index -1) counts as not claimed.
    """
    claimed = result.index >= 0
    labels = np.zeros(len(result.index), dtype=np.int8)
    answered = np.flatnonzero(claimed)
    labels[answered] = truth.label_of(answered, result.index[answered])
    valid = ~(claimed & (labels == EXCLUDED))
    return evaluate(result.confidence, labels == TP, truth.has_loop, valid=valid)


def difference_matrix(method: Method, queries: Any, database: Any) -> tuple[np.ndarray, float, int]:
    """Describe both sides and compare them; returns (D, seconds spent describing, frames)."""
    t0 = time.perf_counter()
    d_db = method.describe(database)
    d_q = method.describe(queries)
    describe_s = time.perf_counter() - t0
    n = len(d_db) + len(d_q)
    D = np.asarray(method.distance(d_q, d_db))
    if D.shape != (len(d_q), len(d_db)):
        raise DataError(
            f"method {method.name!r}: distance returned shape {D.shape}, "
            f"expected ({len(d_q)}, {len(d_db)})"
        )
    return D, describe_s, n


def evaluate_method(
    method: Method,
    queries: Any,
    database: Any,
    truth: GroundTruth,
    *,
    config: EvaluationConfig | None = None,
    revisit: bool = False,
) -> Evaluation:
    """Run `method` on one task's views and score both matching modes."""
    cfg = config or EvaluationConfig()
    D, describe_s, n = difference_matrix(method, queries, database)
    limit = truth.db_limit() if revisit else None
    matches: dict[str, MatchResult] = {}
    seconds: dict[str, float] = {}
    for mode in MODES:
        t0 = time.perf_counter()
        matches[mode] = match(D, cfg.matcher(mode), db_limit=limit)
        seconds[mode] = time.perf_counter() - t0
    metrics = {mode: score_matches(truth, matches[mode]) for mode in MODES}
    metrics["single_frame"].recall_at_n = retrieval_recall(
        D, truth.has_loop, lambda q, j: truth.label_of(q, j) == TP, RECALL_AT, db_limit=limit)
    return Evaluation(matches, metrics, describe_s, n, seconds["sequence"])
