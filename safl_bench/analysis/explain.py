"""Why a cell scored what it did: one PNG of a result record's matrices, matches and mistakes.

`explain` reads the record of one (method, task, seed) cell, rebuilds the method with the
record's parameters and weights and the matcher with the record's settings (`EvaluationConfig
.from_dict`), opens the task through the runner (`runner._task`, so every data-source option of
`safl-bench run` applies), reads the cached views and recomputes only what a record does not
hold: the descriptors, the difference matrix, the enhanced matrix and the matches of one
matching mode (`mode`: the sequence matcher's by default, or single-frame matching).

A retrieval method (`safl_bench.methods.retrieval`) has no descriptors and no difference
matrix, and its record holds everything else: each scored query's matched frame and confidence
(single-frame mode, the only one it has). Its cell is explained from those without running the
method again; its matches then go through the same labelling, measures and figure as any
other's, and the figure says in the place of the matrices that it has none. The sequence mode
of a retrieval method is a ConfigError (the sequence matcher needs the matrix).

`draw` writes the figure:

1. the difference matrix and the contrast-enhanced one side by side (the paper's Figure 4), or,
   for a retrieval method, a line saying why there is none;
2. the database frame each query was matched to against its true one, over the query index;
3. each query's confidence, correct or wrong, with the most confident wrong match as a line:
   recall at 100 % precision counts only the correct matches above it;
4. the most confident wrong matches (`top`, default 4): the query's top view, the wrongly
   matched database top view and the true database top view, side by side.

A query's "true" database frame is its nearest true match (within the task's true-positive
radius, among the frames it may match); a query without one has no true frame.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench.errors import ConfigError, DataError
from safl_bench.evaluation.cell import (
    choose_window,
    compare,
    describe_pair,
    match_outcomes,
    score_matches,
    scored_queries,
    subset_result,
    subset_truth,
)
from safl_bench.evaluation.metrics import AMBIGUOUS, Metrics, true_place_ranks
from safl_bench.evaluation.metrics import CORRECT as CORRECT_LABEL
from safl_bench.evaluation.metrics import WRONG as WRONG_LABEL
from safl_bench.matching.matcher import MatcherConfig, MatchResult, enhanced_matrix, match
from safl_bench.matching.settings import MODES, EvaluationConfig
from safl_bench.matching.window import RECORD_KEY
from safl_bench.methods.method import Method, method_input
from safl_bench.methods.retrieval import NO_SEQUENCE_WHY, is_retrieval
from safl_bench.results.records import (
    ResultRecord,
    default_results_dir,
    load_record,
    record_path,
    rerun_command,
)

#: Per-query outcome codes of `Explanation.status`.
CORRECT, WRONG, BAND, NO_MATCH, NOT_SCORED = "correct", "wrong", "ambiguous band", "no match", "not scored"

_SCORE_WORDS = {
    "min": "-S, the negated lowest mean difference",
    "ratio": "-S/S2, best S over the best elsewhere, negated",
    "inverse": "min(1/S, 1), S the trajectory sum",
}

#: What answered each query, per matching mode (a retrieval method: its own top candidate).
_MATCHED_BY = {"sequence": "the sequence matcher", "single_frame": "single-frame matching"}


@dataclass
class Explanation:
    """Everything `draw` shows, for tests and for other figures."""

    record: ResultRecord
    record_path: Path
    config: EvaluationConfig
    mode: str  # the matching mode explained: "sequence" or "single_frame"
    #: (Nq, Ndb) the method's differences, lower = more similar; None for a retrieval method
    D: np.ndarray | None
    #: (Nq, Ndb) what the mode's matcher reads (matching.enhanced_matrix); None with D
    enhanced: np.ndarray | None
    result: MatchResult  # the mode's answers, every query (a retrieval method: its record's)
    true_index: np.ndarray  # (Nq,) nearest true database frame, -1 where there is none
    status: np.ndarray  # (Nq,) object: CORRECT, WRONG, BAND, NO_MATCH or NOT_SCORED
    distance_m: np.ndarray  # (Nq,) metres between a query and its matched frame (inf: none)
    tp_radius_m: float  # a match this close or closer is correct
    metrics: Metrics  # recomputed from the matches, as the record's were
    worst: list[int]  # the most confident wrong matches (query indices), most confident first
    query_views: Any  # top views of the queries and of the database, for the figure
    database_views: Any
    #: (before, after): per query, the 1-based rank of its nearest true frame in its row of D
    #: and of the enhanced matrix the matcher reads (0: no true place, or not scored); None
    #: for a retrieval method
    true_rank: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def retrieval(self) -> bool:
        """A retrieval method's cell: no matrices, its matches read from its record."""
        return self.record.method.kind == "retrieval"

    @property
    def matcher(self) -> MatcherConfig:
        """The settings of the explained mode's matcher."""
        return self.config.matcher(self.mode)

    @property
    def confidence(self) -> np.ndarray:
        return self.result.confidence

    @property
    def threshold(self) -> float | None:
        """The confidence of the most confident wrong match (None: no wrong match)."""
        return float(self.confidence[self.worst[0]]) if self.worst else None

    @property
    def recorded_recall(self) -> float | None:
        return self.record.results[self.mode].metrics.recall_at_100_precision


def run_command(method: str, task_id: str, *, seed: int | None = None,
                results: str | Path | None = None, source_options: dict[str, Any] | None = None) -> str:
    """The `safl-bench run` command that makes the record `explain` needs."""
    words = ["safl-bench", "run", "--method", method, "--task", task_id]
    if seed is not None:
        words += ["--seed", str(seed)]
    if results is not None:
        words += ["--results", str(results)]
    for flag, value in (source_options or {}).items():
        if value is not None:
            words += [flag, str(value)]
    return " ".join(shlex.quote(w) for w in words)


def rebuild_method(record: ResultRecord) -> Method:
    """The method a record was made with: its parameters and the same weights (the shipped
    ones, the untrained networks, or the same file). ConfigError when that is not possible."""
    from safl_bench.methods.method import make_method
    from safl_bench.run.runner import method_info

    info = record.method.params
    params = dict(info.get("params", {}))
    weights_info = info.get("weights")
    weights: str | None = None
    source: str | None = None
    if isinstance(weights_info, dict):
        kind = weights_info.get("source")
        if kind == "shipped":
            weights, source = "shipped", weights_info.get("picked_for")
        elif kind == "untrained":
            weights = "untrained"
        else:
            weights = weights_info.get("path")
    selected = f"{record.method.name}@{record.method.version}"  # the record's version, not the newest
    method = make_method(selected, weights=weights, source=source, **params)
    if method_info(method).params != info:
        raise ConfigError(f"cannot rebuild {selected} as its record has it (other "
                          "weights or parameters here); rerun the cell with `safl-bench run --force`")
    return method


def explain(method: str, task_id: str, options: Any, *, top: int = 4,
            mode: str | None = None) -> Explanation:
    """Recompute one cell from its record (see the module docstring). `options` is a
    `runner.RunOptions` (results directory, seed, data-source options, progress); `mode` the
    matching mode to explain (None: "sequence", or "single_frame" for a retrieval method). A
    cell without a record is a DataError whose message is the run command that makes it; the
    sequence mode of a retrieval method is a ConfigError."""
    from safl_bench.methods.method import method_class, method_selector, resolve_method
    from safl_bench.run.runner import _task
    from safl_bench.tasks.registry import runnable_spec

    registered = runnable_spec(task_id)  # an old synthetic task cannot be recomputed
    seed = registered.seed if options.seed is None else int(options.seed)
    cls = method_class(resolve_method(method, registered.source))  # what `run` ran there
    retrieval = is_retrieval(cls)
    mode = mode or ("single_frame" if retrieval else "sequence")
    if mode not in MODES:
        raise ConfigError(f"unknown matching mode {mode!r}; modes: {', '.join(MODES)}")
    if retrieval and mode == "sequence":
        raise ConfigError(f"the sequence matcher does not apply to retrieval methods such as "
                          f"{cls.name}@{cls.version} ({NO_SEQUENCE_WHY}); explain its "
                          "single_frame matches")
    path = record_path(options.results_dir, cls.name, cls.version, registered.id, seed)
    if not path.is_file():
        given = None if options.results_dir == default_results_dir() else options.results_dir
        command = run_command(method_selector(cls.name, cls.version, registered.source),
                              registered.id, seed=options.seed, results=given,
                              source_options=_source_flags(options))
        raise DataError(f"no record of {cls.name}@{cls.version} on {registered.id} seed {seed} in "
                        f"{options.results_dir}; make it with: {command}")
    record = load_record(path)
    config = EvaluationConfig.from_dict(record.matcher)
    matcher = config.matcher(mode)
    described = None if retrieval else rebuild_method(record)
    task = _task(registered, seed, options, options.progress, described)
    kind = "topview" if described is None else described.input_kind
    task.prepare(list(dict.fromkeys([kind, "topview"])))
    queries, database, truth = task.queries(kind), task.database(kind), task.truth_for(config)
    q_top, db_top = task.queries("topview"), task.database("topview")
    if config.max_frames is not None:
        n = config.max_frames
        queries, database, q_top, db_top = queries[:n], database[:n], q_top[:n], db_top[:n]
        truth = subset_truth(truth, slice(0, n), slice(0, n))
    nq = len(q_top)
    scored = scored_queries(nq, config.trim_queries, task.spec.context_queries)
    D = enhanced = None
    ranks: tuple[np.ndarray, np.ndarray] | None = None
    if described is None:
        result = recorded_result(record, mode, nq, scored, matcher)
    else:
        d_q, d_db, _, _ = describe_pair(described, method_input(described, queries),
                                        method_input(described, database))
        D = compare(described, d_q, d_db, config.distance)
        window = None
        if matcher.needs_window:  # the record's choice; recomputed for a record without one
            chosen = record.matcher.get(RECORD_KEY) or {}
            window = chosen.get("window") or choose_window(described, np.asarray(d_db),
                                                           config.distance).window
        limit = truth.db_limit() if task.spec.protocol == "revisit" else None
        result = match(D, matcher, db_limit=limit, enhance_window=window)
        enhanced = enhanced_matrix(D, matcher, enhance_window=window)
        true_lists = [truth.true_matches(i) for i in range(nq)]
        ranks = (true_place_ranks(D, true_lists, db_limit=limit, dtype=matcher.dtype),
                 true_place_ranks(enhanced, true_lists, db_limit=limit, dtype=matcher.dtype))

    part = subset_truth(truth, scored, slice(None)) if scored != slice(0, nq) else truth
    outcomes = match_outcomes(truth, result)  # every query; the metrics see the scored ones
    metrics = score_matches(part, subset_result(result, scored))

    claimed = result.index >= 0
    answered = np.flatnonzero(claimed)
    status = np.full(nq, NOT_SCORED, dtype=object)
    inside = np.zeros(nq, dtype=bool)
    inside[scored] = True
    status[inside & ~claimed] = NO_MATCH
    status[inside & claimed & (outcomes.label == CORRECT_LABEL)] = CORRECT
    status[inside & claimed & (outcomes.label == WRONG_LABEL)] = WRONG
    status[inside & claimed & (outcomes.label == AMBIGUOUS)] = BAND
    distance = np.full(nq, np.inf)
    distance[answered] = truth.distances(answered, result.index[answered])
    true_index = np.full(nq, -1, dtype=np.int64)
    for i in range(nq):
        near = truth.true_matches(i)
        if len(near):
            true_index[i] = int(near[np.argmin(truth.distances(i, near))])
    wrong = np.flatnonzero(status == WRONG)
    order = wrong[np.argsort(-result.confidence[wrong], kind="stable")]
    return Explanation(record=record, record_path=path, config=config, mode=mode, D=D,
                       enhanced=enhanced, result=result, true_index=true_index, status=status, distance_m=distance,
                       tp_radius_m=float(truth.tp_radius),
                       metrics=metrics, worst=[int(i) for i in order[:top]],
                       query_views=q_top, database_views=db_top,
                       true_rank=None if ranks is None else (ranks[0] * inside, ranks[1] * inside))


def recorded_result(record: ResultRecord, mode: str, n_queries: int, scored: slice,
                    config: MatcherConfig) -> MatchResult:
    """The matches a record holds for `mode` as a `MatchResult` over all `n_queries`: each
    scored query's stored matched frame, its confidence as the score (negated: lower = better,
    as `evaluation.cell.top_candidate` makes it), and no match for the queries outside `scored`
    (a record stores only those). DataError, naming the command that recomputes the record,
    when it holds no such matches or not one per scored query."""
    held = record.results.get(mode)
    stored = None if held is None else held.queries
    if stored is None or stored.match is None:
        raise DataError(f"the record of {record.method.name}@{record.method.version} on "
                        f"{record.task.id} seed {record.seed} holds no per-query {mode} matches; "
                        f"recompute it: {rerun_command(record)}")
    outcomes = stored.outcomes()
    assert outcomes.match is not None
    n_scored = scored.stop - scored.start
    if len(outcomes.match) != n_scored:
        raise DataError(f"the record of {record.method.name}@{record.method.version} on "
                        f"{record.task.id} holds {len(outcomes.match)} query outcomes, the task "
                        f"scores {n_scored}; recompute it: {rerun_command(record)}")
    index = np.full(n_queries, -1, np.int64)
    index[scored] = outcomes.match
    found = index >= 0
    score = np.full(n_queries, np.inf)
    score[scored] = np.where(outcomes.match >= 0, -outcomes.confidence, np.inf)
    return MatchResult(index=index, score=score, best_s=score.copy(),
                       velocity=np.full(n_queries, np.nan), n_terms=found.astype(np.int64),
                       complete=found.copy(), config=config)


def _source_flags(options: Any) -> dict[str, Any]:
    """The data-source options of `options` as `safl-bench run` flags."""
    flags = {"--kitti-root": getattr(options, "kitti_root", None),
             "--bev-root": getattr(options, "bev_root", None)}
    if getattr(options, "bev_root", None) is not None:
        flags["--bev-resolution"] = getattr(options, "bev_resolution_m", None)
    return flags


def _matched_by(ex: Explanation) -> str:
    """What answered the queries, with the record's matcher settings (presets.label)."""
    from safl_bench.matching.presets import label

    if ex.retrieval:
        return "its own top candidates (single-frame, read from its record)"
    return f"{_MATCHED_BY[ex.mode]}, matcher {label(ex.config)}"


def summary(ex: Explanation) -> str:
    """A few lines for the terminal: the metric, and which wrong matches set it."""
    rec = ex.record
    correct = int((ex.status == CORRECT).sum())
    scored = int((ex.status != NOT_SCORED).sum())
    positive = int(ex.metrics.n_positive)
    lines = [f"{rec.method.name}@{rec.method.version} on {rec.task.id} seed {rec.seed}, "
             f"{_matched_by(ex)}: recall at 100 % precision {_pct(ex.metrics.recall_at_100)} "
             f"(record: {_pct(ex.recorded_recall)}); {correct} correct matches: {correct} of the "
             f"{positive} scored queries with a true place (Recall@1 "
             f"{_pct(correct / positive if positive else float('nan'))}, the tables' "
             f"denominator), of {scored} scored queries in all"]
    enhancement = enhancement_line(ex)
    if enhancement:
        lines.append(enhancement)
    if ex.threshold is not None:
        above = int(((ex.status == CORRECT) & (ex.confidence > ex.threshold)).sum())
        lines.append(f"the most confident wrong match outranks all but {above} correct ones:")
        for rank, q in enumerate(ex.worst, 1):
            lines.append(f"  #{rank} query {q} -> database {ex.result.index[q]} "
                         f"({_metres(ex.distance_m[q])} away; true frame "
                         f"{_frame(ex.true_index[q])}), confidence {ex.confidence[q]:.4g}")
    return "\n".join(lines)


def enhancement_line(ex: Explanation) -> str:
    """What contrast enhancement (Eq. 5) did to the true frame's rank in its row: before (the
    method's differences) and after (the matrix the matcher reads), over the scored queries
    with a true place; '' where there is no matrix or no such query."""
    if ex.true_rank is None:
        return ""
    before, after = ex.true_rank
    has = before > 0
    n = int(has.sum())
    if not n:
        return ""
    window = ex.result.enhance_window
    how = ("off" if not window else
           f"window {window} frames" + (", dip rule" if ex.matcher.needs_window else ""))
    return (f"contrast enhancement ({how}): the true frame's median rank in its row "
            f"{np.median(before[has]):g} -> {np.median(after[has]):g}, first in its row for "
            f"{int((before[has] == 1).sum())} -> {int((after[has] == 1).sum())} of the {n} "
            "scored queries with a true place (before -> after enhancement)")


def _pct(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.1f} %"


def _metres(d: float) -> str:
    return f"{d:.2f} m" if d < 100 else f"{d:.0f} m"


def _frame(j: int) -> str:
    return "none" if j < 0 else str(j)


def _matrix_limits(a: np.ndarray) -> tuple[float, float]:
    lo, hi = np.percentile(a, [1, 99])
    return float(lo), float(hi if hi > lo else lo + 1.0)


def draw(ex: Explanation, out: str | Path, *, dpi: int = 80) -> Path:
    """Write the figure (module docstring) to `out` (PNG); returns the path."""
    import matplotlib
    import matplotlib.style
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out = Path(out)
    rec, cfg = ex.record, ex.matcher
    nq, ndb = len(ex.status), len(ex.database_views)
    n_rows = max(1, (len(ex.worst) + 1) // 2)
    top_height = 6.2 if ex.D is not None else 1.0  # a line instead of the matrices
    with matplotlib.style.context("default"):
        fig = Figure(figsize=(16, 17 - (6.2 - top_height) + 2.9 * n_rows), dpi=dpi)
        FigureCanvasAgg(fig)
        grid = fig.add_gridspec(4 + n_rows, 6,
                                height_ratios=[top_height, 3.4, 3.4, 0.35] + [2.9] * n_rows,
                                hspace=0.75, wspace=0.35, left=0.06, right=0.97, top=0.93, bottom=0.02)
        fig.suptitle(
            f"{rec.method.name}@{rec.method.version} on {rec.task.id} (seed {rec.seed}), "
            f"{_matched_by(ex)}: recall at 100 % precision {_pct(ex.metrics.recall_at_100)}, "
            f"ROC AUC {_auc(ex.metrics)}\nrecord {ex.record_path}", fontsize=13)

        # 1. the difference matrix and the enhanced one (paper Fig. 4), or why there are none
        if ex.D is None or ex.enhanced is None:
            ax = fig.add_subplot(grid[0, :])
            ax.axis("off")
            ax.text(0.5, 0.5, f"No difference matrix, so no enhanced one: {rec.method.name} is a "
                    "retrieval method, which answers each query with ranked, verified candidates, "
                    "not a distance to every database frame.\nThe panels below are drawn from its "
                    "record: each scored query's top candidate and the method's own confidence.",
                    ha="center", va="center", fontsize=12, transform=ax.transAxes,
                    bbox={"boxstyle": "round", "facecolor": "0.95", "edgecolor": "0.6"})
        elif cfg.enhance_window:
            how = (f"Eq. 5 over {cfg.enhance_window} database frames, {cfg.enhance_mode}"
                   + ("; shifted to a minimum of 0" if cfg.shift else "; not shifted"))
        else:
            how = "no enhancement (enhance_window=0)" + ("; shifted to 0" if cfg.shift else "")
        if ex.D is not None and ex.enhanced is not None:
            top_row = grid[0, :].subgridspec(1, 2, wspace=0.22)
            for col, (matrix, title) in enumerate([
                    (ex.D, f"Difference matrix D ({rec.method.name}'s distance)"),
                    (ex.enhanced, f"Enhanced matrix: {how}")]):
                ax = fig.add_subplot(top_row[0, col])
                lo, hi = _matrix_limits(matrix)
                image = ax.imshow(matrix, cmap="gray", vmin=lo, vmax=hi, aspect="auto",
                                  interpolation="nearest")
                ax.set_title(title + "\ndarker = more similar", fontsize=11)
                ax.set_xlabel("database frame")
                ax.set_ylabel("query")
                fig.colorbar(image, ax=ax, fraction=0.04, pad=0.02)

        # 2. matched against true database frame
        q = np.arange(nq)
        ax = fig.add_subplot(grid[1, :])
        has_true = ex.true_index >= 0
        ax.plot(q[has_true], ex.true_index[has_true], "o", ms=5, mfc="none", color="0.55",
                label="true database frame (nearest within the true-positive radius)")
        for status, style, colour in ((CORRECT, ".", "tab:green"), (WRONG, "x", "tab:red"),
                                      (BAND, "+", "tab:orange"), (NOT_SCORED, ".", "0.75")):
            sel = (ex.status == status) & (ex.result.index >= 0)
            if sel.any():
                ax.plot(q[sel], ex.result.index[sel], style, ms=5, color=colour,
                        label=f"matched: {status} ({int(sel.sum())})")
        for rank, i in enumerate(ex.worst, 1):
            ax.annotate(f"#{rank}", (i, ex.result.index[i]), textcoords="offset points",
                        xytext=(4, 4), fontsize=10, color="tab:red", weight="bold")
        _shade_unscored(ax, ex)
        n_none = int((ex.status == NO_MATCH).sum())
        by = "the method (its top candidate)" if ex.retrieval else _MATCHED_BY[ex.mode]
        ax.set_title(f"Database frame matched to each query by {by}, against the "
                     "true one" + (f" ({n_none} scored queries got no match)" if n_none else ""),
                     fontsize=11)
        ax.set_xlabel("query")
        ax.set_ylabel("database frame")
        ax.set_xlim(-1, nq)
        ax.set_ylim(-1, ndb)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), fontsize=9, ncol=4, frameon=False)

        # 3. confidence per query
        ax = fig.add_subplot(grid[2, :])
        conf = ex.confidence
        for status, style, colour in ((CORRECT, "o", "tab:green"), (WRONG, "x", "tab:red"),
                                      (BAND, "+", "tab:orange"), (NOT_SCORED, ".", "0.75")):
            sel = (ex.status == status) & np.isfinite(conf)
            if sel.any():
                ax.plot(q[sel], conf[sel], style, ms=4, color=colour,
                        label=f"{status} ({int(sel.sum())})")
        if ex.threshold is not None:
            above = int(((ex.status == CORRECT) & (conf > ex.threshold)).sum())
            ax.axhline(ex.threshold, color="tab:red", ls="--", lw=1,
                       label=f"most confident wrong match: {above} correct matches above it "
                             "count for recall at 100 % precision")
            for rank, i in enumerate(ex.worst, 1):
                ax.annotate(f"#{rank}", (i, conf[i]), textcoords="offset points", xytext=(4, 4),
                            fontsize=10, color="tab:red", weight="bold")
        _shade_unscored(ax, ex)
        _shade_short(ax, ex)
        score = ("the method's own confidence, from its record" if ex.retrieval else
                 f"score={cfg.score}: {_SCORE_WORDS.get(cfg.score, cfg.score)}")
        ax.set_title(f"Confidence of each query's match ({score}); higher = accepted first",
                     fontsize=11)
        ax.set_xlabel("query")
        ax.set_ylabel("confidence")
        ax.set_xlim(-1, nq)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), fontsize=9, ncol=3, frameon=False)

        # 4. the most confident wrong matches
        head = fig.add_subplot(grid[3, :])
        head.axis("off")
        head.text(0.5, 0.0, "The most confident wrong matches (they set recall at 100 % "
                  "precision): query top view, wrongly matched database top view, true database "
                  "top view" if ex.worst else "No wrong match among the scored queries",
                  ha="center", va="bottom", fontsize=12, transform=head.transAxes)
        for rank, i in enumerate(ex.worst, 1):
            row, col = 4 + (rank - 1) // 2, 3 * ((rank - 1) % 2)
            j, t = int(ex.result.index[i]), int(ex.true_index[i])
            short = ("" if ex.result.complete[i] else
                     f"\nshortened trajectory: {ex.result.n_terms[i]} of {cfg.ds + 1} queries")
            panels = [
                (ex.query_views[i], f"#{rank} query {i}, confidence {conf[i]:.4g}{short}"),
                (ex.database_views[j], f"matched: database {j}, wrong:\n{_metres(ex.distance_m[i])} away (> {ex.tp_radius_m:g} m)"),
                (ex.database_views[t] if t >= 0 else None,
                 f"true: database {t}" if t >= 0 else "no true database frame"),
            ]
            for k, (view, title) in enumerate(panels):
                ax = fig.add_subplot(grid[row, col + k])
                if view is not None:
                    ax.imshow(np.asarray(view), cmap="gray", vmin=0, vmax=1, interpolation="nearest")
                ax.set_title(title, fontsize=10, color="tab:red" if k == 1 else "black")
                ax.set_xticks([])
                ax.set_yticks([])
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, format="png")
    return out


def _auc(metrics: Metrics) -> str:
    return "n/a" if metrics.roc_auc is None else f"{metrics.roc_auc:.3f}"


def _shade_unscored(ax: Any, ex: Explanation) -> None:
    """Grey bands over the queries left out of the metrics (the task's context queries and
    `trim_queries`)."""
    unscored = ex.status == NOT_SCORED
    edges = np.flatnonzero(np.diff(np.concatenate([[0], unscored.astype(np.int8), [0]])))
    for k, (a, b) in enumerate(zip(edges[::2], edges[1::2], strict=True)):
        ax.axvspan(a - 0.5, b - 0.5, color="0.9", zorder=0,
                   label="left out of the metrics (context queries, trim_queries)" if k == 0 else None)


def _shade_short(ax: Any, ex: Explanation) -> None:
    """Yellow bands over the queries whose trajectory was shortened (edge_queries="shorten")."""
    short = (ex.result.index >= 0) & ~ex.result.complete
    if not short.any():
        return
    edges = np.flatnonzero(np.diff(np.concatenate([[0], short.astype(np.int8), [0]])))
    for k, (a, b) in enumerate(zip(edges[::2], edges[1::2], strict=True)):
        ax.axvspan(a - 0.5, b - 0.5, color="gold", alpha=0.25, zorder=0,
                   label="shortened trajectory (fewer than ds + 1 queries)" if k == 0 else None)


def explain_to_png(method: str, task_id: str, options: Any, out: str | Path, *,
                   top: int = 4) -> tuple[Explanation, Path]:
    """`explain` then `draw`."""
    ex = explain(method, task_id, options, top=top)
    return ex, draw(ex, out)
