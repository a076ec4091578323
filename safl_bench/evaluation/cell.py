"""Evaluation of one method on one task: descriptors → difference matrix → matches → metrics.

This is the batch evaluation that every result record comes from. Both matching modes run on
the same difference matrix: the shared SeqSLAM matcher ("sequence") and the nearest database
frame ("single_frame"), so a reader sees what the sequence search adds. Revisit tasks restrict
each query to the database frames it may match (`GroundTruth.db_limit`). Single-frame results
also carry Recall@N (`RECALL_AT`), the retrieval literature's measure, from the same matrix.

Three evaluation-level settings (`EvaluationConfig`; all off by default, the paper's protocol)
reproduce the authors' public code (`safl_bench.matching.presets`, presets "authors",
"authors-sad", "authors-2018"): ``max_frames`` keeps only the first N of the task's frames on
both sides (their ``test_len``), ``trim_queries`` matches every query but leaves the first and
last N out of the metrics (their PR curve starts some queries in), and ``distance`` says how
descriptors are compared: "method" (the method's own `Method.distance`; Eq. 4's squared
Euclidean for the learned methods) or "euclidean" (the plain L2 norm, ``np.linalg.norm`` of
the difference, as the authors' ``Euclidean`` in src/util/utils.py lines 72-77 at commit
``25be0fd``; contrast enhancement is not invariant to squaring). The matches keep every query
either way.
"""

from __future__ import annotations

import dataclasses
import hashlib
import time
import warnings
import weakref
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from safl_bench.common import progress
from safl_bench.common.parallel import Parallel
from safl_bench.errors import ConfigError, DataError
from safl_bench.evaluation.groundtruth import EXCLUDED, TP, GroundTruth
from safl_bench.evaluation.metrics import (
    RECALL_AT,
    Metrics,
    Outcomes,
    evaluate_outcomes,
    outcomes,
    true_place_ranks,
)
from safl_bench.matching import blocks, candidates
from safl_bench.matching.matcher import MatcherConfig, MatchResult
from safl_bench.matching.settings import (  # noqa: F401  (re-exported: they were defined here)
    DISTANCES,
    EVALUATION_SETTINGS,
    MODES,
    RENAMED_PRESETS,
    EvaluationConfig,
    same_settings,
)
from safl_bench.matching.window import WindowChoice, dip_window, sample_rows
from safl_bench.methods.distance import euclidean
from safl_bench.methods.method import Method
from safl_bench.methods.retrieval import NOT_RETRIEVED, Retrieval, RetrievalMethod, is_retrieval


@dataclass
class Evaluation:
    """What one evaluation produced: matches, per-query outcomes and measures per mode, and how
    long each stage took."""

    matches: dict[str, MatchResult]
    outcomes: dict[str, Outcomes]
    metrics: dict[str, Metrics]
    describe_s: float  # both sides, all frames, in the method's own batching
    n_described: int
    matcher_s: float  # the sequence matcher on the difference matrix
    #: retrieval methods: the method's own seconds per query (`Retrieval.seconds`; a method that
    #: does not time its queries: its whole call's time spread evenly); None for descriptor ones
    query_s: np.ndarray | None = None
    #: the ``dip`` rule's enhancement window for this cell's database (None: a fixed window)
    window: WindowChoice | None = None


def match_outcomes(truth: GroundTruth, result: MatchResult,
                   ranks: np.ndarray | None = None,
                   relative_pose: np.ndarray | None = None) -> Outcomes:
    """The label layer: each query's reported match labelled against the task's ground truth
    (`safl_bench.evaluation.metrics` defines what each label counts as). A match in the band between the
    true- and false-positive radii is ambiguous; a match to a frame the query may not match is
    wrong; a query the matcher could not answer (index -1) reported no match. Each query's
    matched database frame is kept (`Outcomes.match`) for the loop-closure stage."""
    claimed = result.index >= 0
    labels = np.zeros(len(result.index), dtype=np.int8)
    answered = np.flatnonzero(claimed)
    labels[answered] = truth.label_of(answered, result.index[answered])
    return outcomes(result.confidence, claimed & (labels == TP), truth.has_loop,
                    ambiguous=claimed & (labels == EXCLUDED), has_candidate=truth.has_candidate,
                    true_rank=ranks, match=np.where(claimed, result.index, -1),
                    relative_pose=relative_pose)


def score_matches(truth: GroundTruth, result: MatchResult) -> Metrics:
    """The measures of one matcher's answers against the task's ground truth."""
    return evaluate_outcomes(match_outcomes(truth, result))


def describe(method: Method, views: Any, parallel: Parallel | None = None
             ) -> tuple[np.ndarray, float]:
    """(descriptors, seconds of describing them): through the descriptor cache for methods that
    ask for it (`Method.cache_descriptors`; the seconds are then those measured when each view was
    described), else directly. Through the cache describing is checkpointed in chunks (an
    interrupted cell resumes from its last chunk) and the cell's progress counts each chunk
    (`safl_bench.common.progress`); a method without the cache describes in one call, its
    frames counted when it returns (chunking it would change its batching, and nothing would
    keep the chunks).

    `parallel` (local workers or a Ray cluster) spreads a cell's describing over its slots when
    it has at least `SPREAD_FRAMES` views: chunks of views described on the workers
    (`spread_describe`), through the cache too. The seconds are then the workers' own, summed
    (so frames per second stays one process's speed, comparable with a serial run)."""
    spread = _spreads(parallel, len(views))
    if getattr(method, "cache_descriptors", False) and method.input_kind == "topview":
        from safl_bench.methods.descriptor_cache import cached_describe

        desc, per_frame, _ = (cached_describe(method, views, parallel=parallel) if spread
                              else cached_describe(method, views))
        return desc, per_frame * len(desc)
    if spread and parallel is not None:
        return spread_describe(method, views, parallel)
    t0 = time.perf_counter()
    desc = method.describe(views)
    seconds = time.perf_counter() - t0
    progress.advance(len(views))
    return desc, seconds


#: A cell's describing is spread over the workers (`describe`'s `parallel`) from this many
#: views on: below it a pool's start-up costs more than it saves.
SPREAD_FRAMES = 2048


def _spreads(parallel: Parallel | None, n: int) -> bool:
    return parallel is not None and not parallel.serial and n >= SPREAD_FRAMES


def spread_describe(method: Method, views: Any, parallel: Parallel) -> tuple[np.ndarray, float]:
    """`method.describe` of `views` in chunks on `parallel`'s workers (`describe_chunks`),
    concatenated in order; the seconds are the workers' own, summed. The descriptors are those
    of one call for methods that describe each view independently of its batch (what
    `safl_bench.methods.check` tests, and the descriptor cache assumes)."""
    from safl_bench.methods.descriptor_cache import describe_chunks

    pieces = describe_chunks(method, views, parallel)
    desc = np.concatenate([p[0] for p in pieces]) if pieces else method.describe(views)
    return desc, float(sum(p[1] for p in pieces))


DatabaseMemo = dict[tuple[int, str], tuple[np.ndarray, float]]
"""Database descriptors already described in this process: (id of the method, digest of the
database views) -> (descriptors, seconds they took when described)."""


def views_digest(views: Any) -> str:
    """BLAKE2b of a view array's bytes, shape and dtype: equal digests, equal views."""
    array = np.ascontiguousarray(views)
    digest = hashlib.blake2b(array.tobytes(), digest_size=16, person=b"safl-db")
    digest.update(f"{array.shape}{array.dtype}".encode())
    return digest.hexdigest()


def describe_database(method: Method, database: Any, memo: DatabaseMemo | None = None,
                      parallel: Parallel | None = None) -> tuple[np.ndarray, float]:
    """`describe` of the database views, through `memo` when given: the seeds of a cell (and the
    paper conditions of one sequence) share their clean database views, so they are described
    once per process and method, and the seconds are those measured then. Views that are not one
    array (point lists) are described each time."""
    if memo is None or not isinstance(database, np.ndarray):
        return describe(method, database, parallel)
    key = (id(method), views_digest(database))
    if key not in memo:
        if len(memo) >= _MEMO_LIMIT:
            memo.pop(next(iter(memo)))
        memo[key] = describe(method, database, parallel)
    else:
        progress.advance(len(database))
    return memo[key]


_MEMO_LIMIT = 8


def compare(method: Method, a: np.ndarray, b: np.ndarray, distance: str = "method") -> np.ndarray:
    """The difference of descriptors `a` (rows) to `b` (columns): `Method.distance` for
    `distance` "method", plain L2 for "euclidean"; a DataError when the method's distance
    returns another shape."""
    D = np.asarray(euclidean(a, b) if distance == "euclidean" else method.distance(a, b))
    if D.shape != (len(a), len(b)):
        raise DataError(
            f"method {method.name!r}: distance returned shape {D.shape}, "
            f"expected ({len(a)}, {len(b)})"
        )
    return D


def describe_pair(method: Method, queries: Any, database: Any, memo: DatabaseMemo | None = None,
                  parallel: Parallel | None = None) -> tuple[np.ndarray, np.ndarray, float, int]:
    """(query descriptors, database descriptors, seconds spent describing, frames described).
    `memo`: database descriptors described before in this process (`describe_database`);
    `parallel`: workers to spread a large side's describing over (`describe`)."""
    progress.expect(len(queries) + len(database))
    d_db, s_db = describe_database(method, database, memo, parallel)
    d_q, s_q = describe(method, queries, parallel)
    return d_q, d_db, s_db + s_q, len(d_db) + len(d_q)


def difference_matrix(method: Method, queries: Any, database: Any, distance: str = "method",
                      memo: DatabaseMemo | None = None) -> tuple[np.ndarray, float, int]:
    """Describe both sides and compare them (`distance`: "method" = `Method.distance`,
    "euclidean" = plain L2); returns (D, seconds spent describing, frames).
    `memo`: database descriptors described before in this process (`describe_database`)."""
    d_q, d_db, describe_s, n = describe_pair(method, queries, database, memo)
    return compare(method, d_q, d_db, distance), describe_s, n


def choose_window(method: Method, database_descriptors: np.ndarray,
                  distance: str = "method") -> WindowChoice:
    """The ``dip`` rule's enhancement window for this database (`safl_bench.matching.window`):
    the self-difference of `DIP_ROWS` database frames to all of them, by the cell's distance.
    The cells that share a database (the seeds and conditions of a paper-protocol sequence get
    the very descriptor array from `describe_database`'s memo) share its choice: it is kept
    while that array lives, so the rule is measured once per database and method."""
    key = (id(method), id(database_descriptors), distance)
    held = _WINDOWS.get(key)
    if held is not None and held[0]() is database_descriptors and held[1]() is method:
        return held[2]
    at = sample_rows(len(database_descriptors))
    rows = compare(method, database_descriptors[at], database_descriptors, distance)
    choice = dip_window(rows, at)
    if len(_WINDOWS) >= _MEMO_LIMIT:
        _WINDOWS.pop(next(iter(_WINDOWS)))
    _WINDOWS[key] = (weakref.ref(database_descriptors), weakref.ref(method), choice)
    return choice


#: `choose_window`'s choices: (method, descriptors, distance) ids -> (the descriptors, the
#: method, the choice), checked by identity before reuse.
_WINDOWS: dict[tuple[int, int, str], tuple[weakref.ref[Any], weakref.ref[Any], WindowChoice]] = {}


def evaluate_method(
    method: Method,
    queries: Any,
    database: Any,
    truth: GroundTruth,
    *,
    config: EvaluationConfig | None = None,
    revisit: bool = False,
    memo: DatabaseMemo | None = None,
    context: int = 0,
    block_mb: float | None = None,
    parallel: Parallel | None = None,
) -> Evaluation:
    """Run `method` on one task's views and score both matching modes (`config.max_frames`
    limits both sides first; `context`, the task's `TaskSpec.context_queries`, and
    `config.trim_queries` leave queries out of the metrics, not out of the matches: see
    `scored_queries`). `memo`: database descriptors to reuse (`describe_database`).
    `block_mb`: the memory budget of the difference matrix's query blocks
    (`safl_bench.matching.blocks.block_mb`; no result depends on it). `parallel`: local
    workers or a Ray cluster to spread this one cell over: its describing (`describe`) and,
    when the difference matrix takes more than one block, the exact matcher's query spans
    (`blocks.spans`, each searched on a worker); no result depends on it either."""
    cfg = config or EvaluationConfig()
    if cfg.max_frames is not None:
        queries, database = queries[:cfg.max_frames], database[:cfg.max_frames]
        truth = subset_truth(truth, slice(0, cfg.max_frames), slice(0, cfg.max_frames))
    if is_retrieval(method):
        return evaluate_retrieval(method, queries, database, truth, config=cfg, revisit=revisit,
                                  context=context)
    d_q, d_db, describe_s, n = describe_pair(method, queries, database, memo, parallel)
    limit = truth.db_limit() if revisit else None
    window: WindowChoice | None = None
    t0 = time.perf_counter()
    if cfg.sequence.needs_window:  # part of the sequence matcher's time
        window = choose_window(method, d_db, cfg.distance)
    window_s = time.perf_counter() - t0
    nq = len(d_q)
    scored = scored_queries(nq, cfg.trim_queries, context)
    part = subset_truth(truth, scored, slice(None)) if scored != slice(0, nq) else truth
    ranks = np.zeros(part.n_queries, np.int64)
    start, stop = int(scored.start), int(scored.stop)

    def rank_rows(a: int, rows: np.ndarray) -> None:
        """The true places' single-frame ranks of the scored queries among rows [a, ...)."""
        lo, hi = max(a, start), min(a + len(rows), stop)
        if hi > lo:
            ranks[lo - start:hi - start] = true_place_ranks(
                rows[lo - a:hi - a], [part.true_matches(i - start) for i in range(lo, hi)],
                db_limit=None if limit is None else limit[lo:hi], dtype=cfg.single_frame.dtype)

    configs = [cfg.matcher(mode) for mode in MODES]
    windows = [window.window if c.needs_window and window else None for c in configs]
    if cfg.candidates is not None:
        results, seconds, ranks = _through_candidates(method, d_q, d_db, cfg, configs, windows,
                                                      limit, part, scored, block_mb)
    else:
        results, seconds = _exact(method, d_q, d_db, cfg, configs, windows, limit, block_mb,
                                  rank_rows, parallel, ranks, part, scored)
    matches = dict(zip(MODES, results, strict=True))
    per_query = {mode: match_outcomes(part, subset_result(matches[mode], scored),
                                      ranks if mode == "single_frame" else None)
                 for mode in MODES}
    metrics = {mode: evaluate_outcomes(per_query[mode], recall_at=RECALL_AT) for mode in MODES}
    return Evaluation(matches, per_query, metrics, describe_s, n, window_s + seconds[0],
                      window=window)


def _exact(method: Method, d_q: np.ndarray, d_db: np.ndarray, cfg: EvaluationConfig,
           configs: list[MatcherConfig], windows: list[int | None], limit: np.ndarray | None,
           block_mb: float | None, visit: Any, parallel: Parallel | None = None,
           ranks: np.ndarray | None = None, part: GroundTruth | None = None,
           scored: slice | None = None) -> tuple[list[MatchResult], list[float]]:
    """Both modes by the exact matcher, the difference matrix in query blocks
    (`safl_bench.matching.blocks`), or whole for a distance that is not row-wise. With
    `parallel` and more than one block, the query spans are searched on its workers
    (`_spread_exact`), and the true places' ranks of the scored queries land in `ranks`."""
    nq, ndb = len(d_q), len(d_db)
    step = blocks.block_rows(nq, ndb, block_mb)
    rowwise = getattr(method, "rowwise_distance", True)
    if (parallel is not None and not parallel.serial and step < nq and rowwise
            and ranks is not None and part is not None and scored is not None):
        return _spread_exact(method, d_q, d_db, cfg, configs, windows, limit, step, parallel,
                             ranks, part, scored)
    if step >= nq or rowwise:
        def rows(a: int, b: int) -> np.ndarray:
            return compare(method, d_q[a:b], d_db, cfg.distance)
    else:
        _say_dense(method, nq, ndb)
        D = compare(method, d_q, d_db, cfg.distance)
        step = nq

        def rows(a: int, b: int) -> np.ndarray:
            return D[a:b]
    return blocks.match_rows(rows, nq, ndb, configs, db_limit=limit, block=step, visit=visit,
                             windows=windows)


def _spread_exact(method: Method, d_q: np.ndarray, d_db: np.ndarray, cfg: EvaluationConfig,
                  configs: list[MatcherConfig], windows: list[int | None],
                  limit: np.ndarray | None, step: int, parallel: Parallel, ranks: np.ndarray,
                  part: GroundTruth, scored: slice) -> tuple[list[MatchResult], list[float]]:
    """The exact matcher with its query spans (`blocks.spans`, whole blocks of `step` rows, one
    or more per slot) searched on `parallel`'s workers, each span computing its own blocks of
    the difference matrix (`_span_job`): the same blocks, so the same numbers, as the serial
    pass; `blocks.combine` joins them. Each worker holds one block's rows at a time, so the
    memory budget (`--block-mb`) is per worker."""
    from safl_bench.common.parallel import run_jobs

    nq = len(d_q)
    start, stop = int(scored.start), int(scored.stop)
    limits = blocks.db_limits(limit, nq, len(d_db))
    reach = [c.u_range() for c in configs]
    u_lo, u_hi = min(u for u, _ in reach), max(u for _, u in reach)
    jobs = []
    for first, last in blocks.spans(nq, step, 2 * parallel.slots()):
        lo = max(0, first + u_lo) // step * step  # the blocks this span computes
        hi = min(nq, -(-min(nq, last + u_hi) // step) * step)
        truths = [part.true_matches(i - start) for i in range(max(first, start), min(last, stop))]
        jobs.append((method, cfg.distance, d_q[lo:hi], lo, d_db, configs, windows, limits, step,
                     (first, last), nq, truths, start, stop, cfg.single_frame.dtype))
    done = run_jobs(_span_job, jobs, parallel)
    failed = [r.error for r in done if r.error is not None]
    if failed:
        raise DataError(f"the exact matcher's query spans failed on the workers: {failed[0]}")
    spans = []
    for (span, span_ranks) in (r.value for r in done):
        spans.append(span)
        a, b = max(span.first, start), min(span.stop, stop)
        if b > a:
            ranks[a - start:b - start] = span_ranks
    return blocks.combine(configs, spans, nq, len(d_db), windows=windows)


def _span_job(method: Method, distance: str, d_q: np.ndarray, offset: int, d_db: np.ndarray,
              configs: list[MatcherConfig], windows: list[int | None], limit: np.ndarray,
              step: int, span: tuple[int, int], nq: int, truths: list[np.ndarray], start: int,
              stop: int, dtype: str) -> tuple[blocks.SpanResult, np.ndarray]:
    """One worker's query span (`_spread_exact`): `d_q` holds query rows ``[offset, ...)``
    (the blocks the span reads); the span's result and the single-frame ranks of its scored
    queries (``[max(first, start), min(last, stop))``, their true places `truths`)."""
    first, last = span
    a0, b0 = max(first, start), min(last, stop)
    out = np.zeros(max(b0 - a0, 0), np.int64)

    def rows(a: int, b: int) -> np.ndarray:
        return compare(method, d_q[a - offset:b - offset], d_db, distance)

    def rank_rows(a: int, raw: np.ndarray) -> None:
        lo, hi = max(a, a0), min(a + len(raw), b0)
        if hi > lo:
            out[lo - a0:hi - a0] = true_place_ranks(
                raw[lo - a:hi - a], truths[lo - a0:hi - a0], db_limit=limit[lo:hi], dtype=dtype)

    result = blocks.search_span(rows, nq, len(d_db), configs, span, db_limit=limit,
                                windows=windows, block=step, visit=rank_rows)
    return result, out


def check_candidates(method: Any, cfg: EvaluationConfig) -> None:
    """A ConfigError when `cfg` asks for the candidate search and `method`'s descriptors cannot
    be searched by L2 (its own distance, under ``distance=method``); nothing else."""
    if cfg.candidates is None or is_retrieval(method):
        return
    own = getattr(type(method), "distance", Method.distance) is not Method.distance
    if cfg.distance == "method" and own:
        raise ConfigError(f"candidates={cfg.candidates}: the candidate search compares descriptors "
                          f"by L2, but method {method.name!r} has its own distance; give "
                          f"--matcher distance=euclidean to search its descriptors by L2, or "
                          f"leave candidates unset (the exact matcher)")


def _through_candidates(method: Method, d_q: np.ndarray, d_db: np.ndarray,
                        cfg: EvaluationConfig, configs: list[MatcherConfig],
                        windows: list[int | None], limit: np.ndarray | None, part: GroundTruth,
                        scored: slice, block_mb: float | None = None,
                        ) -> tuple[list[MatchResult], list[float], np.ndarray]:
    """Both modes through each query's ``cfg.candidates`` nearest frames
    (`safl_bench.matching.candidates`), the single-frame ranks among them; the candidate
    search's time counts to the sequence matcher's. The ``flat`` index reads the exact
    matcher's difference rows (`compare`), in blocks under `block_mb`; ``ivf`` is FAISS's."""
    check_candidates(method, cfg)
    k = int(cfg.candidates or 0)
    if cfg.index == "flat":
        nq, ndb = len(d_q), len(d_db)

        def rows(a: int, b: int) -> np.ndarray:
            return compare(method, d_q[a:b], d_db, cfg.distance)

        cand, results, seconds = candidates.search_rows(
            rows, nq, ndb, k, configs, db_limit=limit, windows=windows,
            block=blocks.block_rows(nq, ndb, block_mb, copies=2))
    else:
        t0 = time.perf_counter()
        cand = candidates.nearest(d_q, d_db, k, index=cfg.index, db_limit=limit)
        search_s = time.perf_counter() - t0
        results, seconds = [], []
        for c, w in zip(configs, windows, strict=True):
            t0 = time.perf_counter()
            results.append(candidates.match_candidates(d_q, d_db, cand, c, db_limit=limit,
                                                       enhance_window=w,
                                                       root=cfg.distance == "euclidean"))
            seconds.append(time.perf_counter() - t0 + search_s)
    sub = candidates.Candidates(cand.index[scored], cand.distance[scored])
    ranks = candidates.candidate_ranks(sub, [part.true_matches(i) for i in range(part.n_queries)],
                                       NOT_RETRIEVED)
    return results, seconds, ranks


def _say_dense(method: Method, nq: int, ndb: int) -> None:
    """One line, once per method class and process: its distance is not row-wise, so the whole
    difference matrix is built (`Method.rowwise_distance`)."""
    kind = type(method)
    if kind in _SAID_DENSE:
        return
    _SAID_DENSE.add(kind)
    warnings.warn(f"method {method.name!r}: its distance is not row-wise (rowwise_distance = "
                  f"False), so the whole {nq} x {ndb} difference matrix is built at once",
                  stacklevel=3)


_SAID_DENSE: set[type] = set()


def evaluate_retrieval(
    method: Method,
    queries: Any,
    database: Any,
    truth: GroundTruth,
    *,
    config: EvaluationConfig,
    revisit: bool = False,
    context: int = 0,
) -> Evaluation:
    """A retrieval method (`safl_bench.methods.retrieval`) on one task's views: its ranked
    candidates, restricted to each query's candidates (`GroundTruth.db_limit` on revisit tasks:
    what it returns beyond them is dropped), become a difference matrix (minus the confidence,
    +inf where not returned), which the single-frame answer and `true_place_ranks` read with
    the one tie rule (a query none of whose true places was returned gets rank `NOT_RETRIEVED`:
    found at no N); only the single-frame mode is scored (no sequence result: no full
    difference matrix). The matched frame's relative pose, where the method gives one, goes to
    the outcomes. Revisit queries are the database frames, so the method is told
    ``same_frames``."""
    cfg = config
    limit = truth.db_limit() if revisit else None
    progress.expect(len(queries))
    t0 = time.perf_counter()
    answer = cast(RetrievalMethod, method).retrieve(queries, database, db_limit=limit,
                                                    same_frames=revisit)
    if not isinstance(answer, Retrieval):
        raise DataError(f"method {method.name!r}: retrieve() must return a Retrieval, got "
                        f"{type(answer).__name__}")
    answer = answer.checked(len(queries), len(database), f"method {method.name!r}")
    seconds = time.perf_counter() - t0
    progress.advance(len(queries))
    D = answer.as_difference(len(database), limit)
    t0 = time.perf_counter()
    result = top_candidate(D, cfg.single_frame)
    matcher_s = time.perf_counter() - t0
    scored = scored_queries(len(D), cfg.trim_queries, context)
    part = subset_truth(truth, scored, slice(None)) if scored != slice(0, len(D)) else truth
    true_places = [part.true_matches(i) for i in range(part.n_queries)]
    ranks = true_place_ranks(D[scored], true_places,
                             db_limit=None if limit is None else limit[scored],
                             dtype=cfg.single_frame.dtype)
    # a true place the method did not return is retrieved at no N (not by the tie rule among
    # the frames it left out): its rank lies beyond every list
    returned = np.isfinite(D[scored])
    missed = [i for i, js in enumerate(true_places) if len(js) and not returned[i, js].any()]
    ranks[missed] = NOT_RETRIEVED
    pose = None
    if answer.pose is not None:
        pose = np.stack([answer.pose_of(i, int(j)) for i, j in enumerate(result.index)])[scored]
    outcome = match_outcomes(part, subset_result(result, scored), ranks, pose)
    mode = "single_frame"
    return Evaluation({mode: result}, {mode: outcome},
                      {mode: evaluate_outcomes(outcome, recall_at=RECALL_AT)},
                      seconds, len(queries), matcher_s,
                      query_s=np.full(len(queries), seconds / max(len(queries), 1))
                      if answer.seconds is None else np.asarray(answer.seconds, np.float64))


def top_candidate(D: np.ndarray, config: MatcherConfig) -> MatchResult:
    """The single-frame answer of a retrieval method from its ranking `D` (`Retrieval.
    as_difference`: lower = better, +inf = not returned or not allowed): per query the first
    minimum in the matcher's precision (`config.dtype`), i.e. the highest confidence and, among
    equal ones, the lower database index (the one tie rule); no match (-1, +inf) when nothing
    was returned. Its score is minus the method's confidence, so the metrics read that
    confidence (`confidence_from_score`). No contrast enhancement nor score rule applies: the
    method's own confidence is the score."""
    Dm = np.asarray(D, dtype=np.dtype(config.dtype))
    n = Dm.shape[0]
    if Dm.shape[1] == 0:
        j = np.zeros(n, np.int64)
        best = np.full(n, np.inf)
    else:
        j = np.argmin(Dm, axis=1).astype(np.int64)
        best = Dm[np.arange(n), j].astype(np.float64)
    found = np.isfinite(best)
    index = np.where(found, j, -1)
    score = np.where(found, best, np.inf)
    return MatchResult(index=index, score=score, best_s=score.copy(),
                       velocity=np.full(n, np.nan), n_terms=found.astype(np.int64),
                       complete=found.copy(), config=config)


def scored_queries(n_queries: int, trim: int, context: int = 0) -> slice:
    """The queries the metrics see, of the `n_queries` matched: all but the task's first
    `context` (`TaskSpec.context_queries`) and the evaluation's first and last `trim`
    (`trim_queries`), i.e. ``[max(context, trim), n_queries - trim)``: both rules leave the same
    leading queries out, so they do not add up. Every method and both matching modes of a task
    are scored on these queries; a query among them that a setting leaves unanswered (e.g.
    ``edge_queries="skip"``) is scored as a query that reported no match."""
    start = max(trim, context)
    if start >= n_queries - trim:
        raise ConfigError(f"trim_queries={trim} and {context} context queries leave none of the "
                          f"{n_queries} queries to evaluate")
    return slice(start, n_queries - trim)


def subset_truth(truth: GroundTruth, queries: slice, database: slice) -> GroundTruth:
    """The ground truth of a slice of the queries and of the database."""
    return dataclasses.replace(
        truth,
        query_positions=truth.query_positions[queries], query_times=truth.query_times[queries],
        database_positions=truth.database_positions[database],
        database_times=truth.database_times[database],
    )


def subset_result(result: MatchResult, queries: slice) -> MatchResult:
    """The matches of a slice of the queries (the whole result for the full slice)."""
    if queries == slice(0, len(result.index)):
        return result
    return dataclasses.replace(
        result, index=result.index[queries], score=result.score[queries],
        best_s=result.best_s[queries], velocity=result.velocity[queries],
        n_terms=result.n_terms[queries], complete=result.complete[queries],
        S=None if result.S is None else result.S[queries])
