"""Resampled queries against re-rendered ones: what "empty corners" cost a method.

On the synthetic default (and on KITTI scans) a noisy query T{a}R{b} is re-rendered from the
local map at the moved viewpoint (`safl_bench.views.topview`); on an image source (BEVPlace's
top views of real KITTI, `safl_bench.sources.bev`) nothing can be re-rendered, so the query is
the clean image resampled to the moved viewpoint (`safl_bench.views.resample.move_viewpoint`),
and what the moved view sees beyond the original image is empty. This module measures the
difference on a source that can do both, with everything else held fixed: the same task,
frames, database, noise draws (the task's `query_offsets`, from its seed), method, weights and
matcher. Each cell (method, task, seed) is evaluated with three sets of queries, the ARMS:

* ``rerendered``: the task's own queries (re-rendered at the noisy viewpoint), what every
  record of the task holds;
* ``resampled``: the clean view of each query frame moved to the same noisy viewpoint with
  `move_viewpoint`, exactly as `safl_bench.views.render` makes an image source's queries
  (nearest neighbour, 0 outside), at the task's pixel size (`MapConfig.cell_m`);
* ``masked``: the re-rendered queries with every pixel that the resampled view leaves empty set
  to 0 (`resample.coverage_masks`): the empty corners without the resampling, so that
  ``masked - rerendered`` is what the missing area costs and ``resampled - masked`` what
  nearest-neighbour resampling of a finished image costs beyond it.

The measures of each arm come from the per-query outcomes with the two-level bootstrap of
`safl_bench.evaluation.uncertainty` (seeds and queries); the differences ``resampled -
rerendered`` and ``masked - rerendered`` are paired (`Sample.minus`: the same resamples on both
sides), so their 95 % intervals say whether the way the queries are made moves a measure
beyond the noise of the benchmark.

Evaluations are kept per (method, task, seed, arm) as compressed ``.npz`` files of the outcomes
in a cells folder, keyed by everything that changes them (`cell_key`), so a rerun with more
tasks or seeds computes only what is missing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench.common.atomic import atomic_path
from safl_bench.common.fingerprint import fingerprint, to_jsonable
from safl_bench.errors import ConfigError, DataError
from safl_bench.evaluation.cell import evaluate_method
from safl_bench.evaluation.metrics import Outcomes
from safl_bench.evaluation.uncertainty import Interval, Sample, sample
from safl_bench.matching.presets import default_config
from safl_bench.matching.settings import MODES, EvaluationConfig
from safl_bench.methods.method import Method, method_input
from safl_bench.run.runner import RunOptions, _task, method_info
from safl_bench.tasks.registry import runnable_spec
from safl_bench.tasks.task import Task
from safl_bench.views.noise import CLEAN
from safl_bench.views.resample import coverage_masks, move_viewpoint

#: The three ways of making the queries (module docstring), in table order.
ARMS = ("rerendered", "resampled", "masked")
#: The paired differences reported, (minuend, subtrahend).
DIFFERENCES = (("resampled", "rerendered"), ("masked", "rerendered"))
#: Bumped when what a cell file holds changes.
CELL_VERSION = 1


def resampled_queries(clean: np.ndarray, offsets: np.ndarray, cell_m: float) -> np.ndarray:
    """The ``resampled`` arm: each clean top view (N, S, S) moved to its viewpoint offset
    `offsets[i]` ([dx, dy] m, dtheta rad) by `move_viewpoint`, float32 as the views."""
    return move_viewpoint(np.asarray(clean, dtype=np.float32), offsets, cell_m)


def masked_queries(rerendered: np.ndarray, offsets: np.ndarray, cell_m: float) -> np.ndarray:
    """The ``masked`` arm: the re-rendered queries, 0 wherever the resampled view is empty."""
    views = np.asarray(rerendered, dtype=np.float32)
    return views * coverage_masks(views.shape[1], offsets, cell_m).astype(np.float32)


def check_task(task: Task) -> None:
    """ConfigError in one line unless `task` re-renders noisy top-view queries (the paper
    protocol with viewpoint noise, on a source with scans)."""
    if task.source is None or task.source.renders != "scans":
        what = "in-memory views" if task.source is None else f"{task.source.label} ({task.source.renders})"
        raise ConfigError(f"task {task.id}: its queries cannot be re-rendered ({what}); compare "
                          "resampled and re-rendered queries on the synthetic default or KITTI scans")
    if task.spec.protocol != "paper" or task.spec.condition.is_clean:
        raise ConfigError(f"task {task.id}: needs the paper protocol with viewpoint noise "
                          f"(protocol {task.spec.protocol}, condition {task.spec.condition})")
    if task.spec.map_config is None:
        raise ConfigError(f"task {task.id}: has no map configuration to take the pixel size from")


def clean_query_views(task: Task) -> np.ndarray:
    """The clean top views of the query frames (the database's own when the frames are the
    same, as in the paper protocol)."""
    if np.array_equal(task.query_frames, task.database_frames):
        return np.asarray(task.database("topview"))
    from safl_bench.views import mapcache

    assert task.source is not None  # check_task
    return np.asarray(mapcache.load_views(task.source, task.spec.sequence, task.spec.map_config,
                                          frames=task.query_frames, condition=CLEAN,
                                          seed=task.spec.seed, kind="topview",
                                          progress=task.progress))


def arm_queries(task: Task) -> dict[str, np.ndarray]:
    """{arm: query views} of one task (`ARMS`), all from the task's own noise draws."""
    check_task(task)
    assert task.spec.map_config is not None
    cell_m = task.spec.map_config.cell_m
    rerendered = np.asarray(task.queries("topview"))
    return {
        "rerendered": rerendered,
        "resampled": resampled_queries(clean_query_views(task), task.query_offsets, cell_m),
        "masked": masked_queries(rerendered, task.query_offsets, cell_m),
    }


def view_agreement(arms: dict[str, np.ndarray], offsets: np.ndarray, cell_m: float,
                   clean: np.ndarray) -> dict[str, float]:
    """How the arms' views differ, over one task's queries: the mean share of each view that
    the resampled one covers, and the mean absolute pixel difference inside that area between
    re-rendered and resampled views (0 if re-rendering only moved the picture) and between
    re-rendered and clean, unmoved views (what the noise itself changes), for reference."""
    masks = coverage_masks(arms["rerendered"].shape[1], offsets, cell_m).astype(bool)
    inside = max(int(masks.sum()), 1)
    return {
        "coverage": float(masks.mean()),
        "abs_diff_resampled": float(np.abs(arms["rerendered"] - arms["resampled"])[masks].sum() / inside),
        "abs_diff_clean": float(np.abs(arms["rerendered"] - clean)[masks].sum() / inside),
    }


def cell_key(method: Method, task: Task, arm: str, evaluation: EvaluationConfig) -> str:
    """Everything that changes one arm's outcomes: the method's name, version and settings
    (weights too), the task's definition, seed and data, the arm and the matcher settings."""
    data = task.source.fingerprint(task.spec.sequence) if task.source is not None else None
    return fingerprint("resampling-cell", CELL_VERSION, to_jsonable(method_info(method)),
                       task.spec.fingerprint, task.spec.seed, task.spec.map_config, data, arm,
                       evaluation.to_dict())


def _save_outcomes(path: Path, per_mode: dict[str, Outcomes]) -> None:
    arrays: dict[str, Any] = {}  # Any: numpy's stub reads **kwargs as allow_pickle
    for mode, o in per_mode.items():
        for name in ("confidence", "label", "has_true_place", "has_candidate", "true_rank"):
            value = getattr(o, name)
            if value is not None:
                arrays[f"{mode}.{name}"] = value
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)


def _load_outcomes(path: Path) -> dict[str, Outcomes] | None:
    """The outcomes of a cell file, None when it is missing or unreadable (then recomputed)."""
    try:
        with np.load(path) as data:
            return {mode: Outcomes(
                confidence=data[f"{mode}.confidence"], label=data[f"{mode}.label"],
                has_true_place=data[f"{mode}.has_true_place"],
                has_candidate=data[f"{mode}.has_candidate"],
                true_rank=data[f"{mode}.true_rank"] if f"{mode}.true_rank" in data else None,
            ) for mode in MODES}
    except (OSError, ValueError, KeyError):
        return None


@dataclass(frozen=True)
class Experiment:
    """What to compare: methods (made by the caller, e.g. with `make_method`), registered task
    ids, the noise seeds of every task, the matcher settings and the matching mode."""

    tasks: tuple[str, ...]
    seeds: tuple[int, ...]
    evaluation: EvaluationConfig = field(default_factory=default_config)
    mode: str = "sequence"
    kitti_root: str | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ConfigError(f"matching mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if not self.tasks or not self.seeds:
            raise ConfigError("the experiment needs at least one task and one seed")


@dataclass
class CellResult:
    """One (method, task): the bootstrap of each arm over the seeds, and the view agreement
    averaged over the seeds."""

    method: str  # name@version
    task_id: str
    condition: str
    seeds: tuple[int, ...]
    n_queries: int
    samples: dict[str, Sample]
    agreement: dict[str, float]

    def intervals(self) -> dict[str, dict[str, Interval]]:
        """{arm: {measure: interval}}."""
        return {arm: s.intervals() for arm, s in self.samples.items()}

    def differences(self) -> dict[str, dict[str, Interval]]:
        """{"A - B": {measure: paired interval}} for each of `DIFFERENCES`."""
        return {f"{a} - {b}": self.samples[a].minus(self.samples[b]) for a, b in DIFFERENCES}


def _cell_path(cells_dir: Path, method: Method, task: Task, arm: str,
               evaluation: EvaluationConfig) -> Path:
    return (cells_dir / f"{method.name}@{method.version}" / task.id.replace("/", "_")
            / f"seed{task.spec.seed}-{arm}-{cell_key(method, task, arm, evaluation)}.npz")


def run(experiment: Experiment, methods: Callable[[str], Sequence[Method]], cells_dir: Path, *,
        progress: bool = True, log: Callable[[str], None] = print) -> list[CellResult]:
    """Evaluate every method on every task and seed with the three arms of queries (cells
    found in `cells_dir` are reused, new ones written there) and bootstrap them. `methods(source)`
    gives the methods for a task's source kind (trained weights differ between sources)."""
    options = RunOptions(results_dir=cells_dir, kitti_root=experiment.kitti_root, progress=progress)
    results: list[CellResult] = []
    for task_id in experiment.tasks:
        registered = runnable_spec(task_id)
        chosen = list(methods(registered.source))
        outcomes: list[dict[str, list[Outcomes]]] = [{a: [] for a in ARMS} for _ in chosen]
        agreement: list[dict[str, float]] = []
        memo: dict[Any, Any] = {}  # database descriptors, described once per method
        for seed in experiment.seeds:
            views: dict[Any, tuple[Task, dict[str, np.ndarray]]] = {}  # by map configuration
            for i, method in enumerate(chosen):
                task = _task(registered, seed, options, progress, method)
                if task.spec.map_config not in views:
                    check_task(task)
                    arms = arm_queries(task)
                    views[task.spec.map_config] = (task, arms)
                    if not i:
                        assert task.spec.map_config is not None
                        agreement.append(view_agreement(arms, task.query_offsets,
                                                        task.spec.map_config.cell_m,
                                                        clean_query_views(task)))
                task, arms = views[task.spec.map_config]
                for arm in ARMS:
                    path = _cell_path(cells_dir, method, task, arm, experiment.evaluation)
                    found = _load_outcomes(path) if path.is_file() else None
                    if found is None:
                        found = evaluate_method(
                            method, method_input(method, arms[arm]),
                            method_input(method, task.database(method.input_kind)),
                            task.truth_for(experiment.evaluation),
                            config=experiment.evaluation, memo=memo,
                            context=task.spec.context_queries).outcomes
                        _save_outcomes(path, found)
                    outcomes[i][arm].append(found[experiment.mode])
        mean_agreement = {k: float(np.mean([a[k] for a in agreement])) for k in agreement[0]}
        for i, method in enumerate(chosen):
            label = f"{method.name}@{method.version}"
            results.append(CellResult(
                label, task_id, registered.condition.name, experiment.seeds,
                len(outcomes[i]["rerendered"][0].confidence),
                {arm: sample(outcomes[i][arm]) for arm in ARMS}, mean_agreement))
            log(f"{task_id} {label}: {len(experiment.seeds)} seed(s) done")
    return results


def check_out(out: Path) -> Path:
    """The output folder, created; DataError in one line when it is a file or not writable."""
    out = Path(out).expanduser()
    if out.exists() and not out.is_dir():
        raise DataError(f"--out {out}: exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"--out {out}: cannot create it ({exc.strerror})") from None
    return out


#: The measures reported by default (names of `uncertainty.measure_names`).
DEFAULT_MEASURES = ("recall_at_100_precision", "authors_recall_at_99p", "auc", "f1_max",
                    "recall_at_1")
_ARM_TITLES = {"rerendered": "re-rendered", "resampled": "resampled", "masked": "masked"}
_AGREEMENT = ("coverage", "abs_diff_resampled", "abs_diff_clean")


def csv_text(results: Sequence[CellResult], measures: Sequence[str]) -> str:
    """One row per (method, task, measure): each arm's mean and 95 % interval, each paired
    difference's, and the task's view agreement (`view_agreement`); fractions, not %."""
    import csv
    import io

    diffs = [f"{a} - {b}" for a, b in DIFFERENCES]
    head = ["method", "task", "condition", "seeds", "n_queries", "measure"]
    for name in [*ARMS, *(d.replace(" - ", "_minus_") for d in diffs)]:
        head += [name, f"{name}_low", f"{name}_high"]
    head += list(_AGREEMENT)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(head)
    for r in results:
        intervals, differences = r.intervals(), r.differences()
        for measure in measures:
            row: list[Any] = [r.method, r.task_id, r.condition, " ".join(map(str, r.seeds)),
                              r.n_queries, measure]
            for iv in [intervals[a].get(measure) for a in ARMS] + [differences[d].get(measure)
                                                                    for d in diffs]:
                row += ["", "", ""] if iv is None else [_number(iv.mean), _number(iv.low),
                                                        _number(iv.high)]
            row += [_number(r.agreement[k]) for k in _AGREEMENT]
            writer.writerow(row)
    return buf.getvalue()


def _number(value: float) -> str:
    return "" if value != value else f"{value:.6f}"


def _difference_cell(iv: Interval | None) -> str:
    if iv is None:
        return "n/a"
    text = iv.format(100)
    return f"**{text}**" if iv.excludes_zero() else text


def markdown_text(results: Sequence[CellResult], measures: Sequence[str],
                  config: dict[str, Any]) -> str:
    """The report: what was compared, the view agreement per task, and per measure a table of
    each arm and the paired differences (in %, AUC and F1 x 100; bold: the interval excludes 0)."""
    seeds = " ".join(map(str, config["seeds"]))
    lines = [
        "# Resampled against re-rendered queries",
        "",
        f"Made by `{config['command']}` (safl-bench {config['safl_bench_version']}, git "
        f"{config['git_revision']}). Matcher preset `{config['matcher']['preset']}`, "
        f"{config['mode']} matching, noise seeds {seeds}; means over the seeds with 95 % "
        "intervals over seeds and queries (`safl_bench.evaluation.uncertainty`), the differences "
        "paired (the same resamples on both sides); **bold**: the difference's interval excludes 0.",
        "",
        "Arms (`safl_bench.analysis.resampling`): **re-rendered** = the task's queries, rendered "
        "from the local map at the noisy viewpoint; **resampled** = the clean view of the same "
        "frame moved to the same noisy viewpoint by `move_viewpoint`, as an image source's "
        "queries are made (what lies outside the image is empty); **masked** = the re-rendered "
        "queries emptied where the resampled ones are empty.",
        "",
        "## The views",
        "",
        "coverage: mean share of a query that the resampled view still covers; |re-rendered - "
        "resampled| and |re-rendered - clean|: mean absolute pixel difference inside that area "
        "(views in [0, 1]).",
        "",
        "| task | condition | coverage | abs. diff. re-rendered - resampled | abs. diff. re-rendered - clean |",
        "|---|---|---:|---:|---:|",
    ]
    seen: set[str] = set()
    for r in results:
        if r.task_id in seen:
            continue
        seen.add(r.task_id)
        a = r.agreement
        lines.append(f"| {r.task_id} | {r.condition} | {100 * a['coverage']:.1f} % | "
                     f"{a['abs_diff_resampled']:.4f} | {a['abs_diff_clean']:.4f} |")
    diffs = [f"{a} - {b}" for a, b in DIFFERENCES]
    for measure in measures:
        lines += ["", f"## {measure}", "",
                  "| method | condition | " + " | ".join(_ARM_TITLES[a] for a in ARMS) + " | "
                  + " | ".join(d.replace(" - ", " − ") for d in diffs) + " |",
                  "|---|---|" + "---:|" * (len(ARMS) + len(diffs))]
        for r in results:
            intervals, differences = r.intervals(), r.differences()
            arms = [intervals[a][measure].format(100) if measure in intervals[a] else "n/a"
                    for a in ARMS]
            ds = [_difference_cell(differences[d].get(measure)) for d in diffs]
            lines.append(f"| {r.method} | {r.condition} | " + " | ".join(arms + ds) + " |")
    return "\n".join(lines) + "\n"
