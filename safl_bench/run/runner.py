"""Running methods over benchmark cells (method × task × seed) into result records.

A cell whose record exists with the same configuration is reused; a corrupt record is reported by
name and recomputed; a record made with other settings (method parameters or weights, matcher,
task definition) is recomputed and replaced. The views of the cells to compute are rendered
first, one pass over the scans per sequence. Records are written atomically as each cell
finishes (in a parallel run, each evaluation is kept on disk as it comes back from a worker),
so an interrupted run resumes where it stopped.

The seed of a cell is the seed of the queries' viewpoint noise (the registered task's seed unless
`--seed` gives another); the record keeps the registered task's fingerprint so records of several
seeds of one task sit in one leaderboard cell.

The seeds of a cell share what does not depend on the seed (`RunOptions.share_seeds`, on by
default): within one run the batch-1 timing (`Timings.describe_ms_per_frame`, `peak_memory_mb`)
is taken once per (method, task), at the first seed the run computes, and the other seeds'
records carry it, saying so in `how_run` ("the cell's timing, measured at seed S"); the database
descriptors are described once per method and database (the clean database views of a cell's
seeds, and of the paper conditions of one sequence, are the same frames), the seconds they took
carried into each record's throughput; and in a serial run the cells of one data source and
sequence open it once (its poses, times and decoded images are read once). Everything else of a record (matches, outcomes, metrics)
is what it would be alone: methods describe each view independently of the others
(`check_method`). `share_seeds=False` describes and times every seed on its own (what
`safl-bench bench seeds` compares against).

Progress (`RunOptions.progress`): on a terminal, a bar over the cells and, under it, one over the
frames the cell in progress describes (`safl_bench.common.progress`; a cell of BEVPlace on a real
sequence describes thousands of frames for minutes, which a bar of cells alone shows as `0/1`).
Where stderr is not a terminal (a log file, CI) there are no bars, whose carriage-return
redraws would fill the log, but one plain line per finished cell. Describing through the
descriptor cache is checkpointed in chunks, so an interrupted cell loses at most one chunk of
descriptors (`safl_bench.methods.descriptor_cache`).
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench.common import progress as frame_progress
from safl_bench.common.parallel import JobResult, Parallel, run_jobs
from safl_bench.errors import ConfigError, SaflError
from safl_bench.evaluation.cell import DatabaseMemo, evaluate_method
from safl_bench.evaluation.metrics import METRICS_VERSION, NoPositivesError
from safl_bench.matching.presets import default_config
from safl_bench.matching.settings import MODES, EvaluationConfig, same_settings
from safl_bench.matching.window import RECORD_KEY, WindowChoice
from safl_bench.methods.method import Method, input_note, method_input, method_selector
from safl_bench.methods.retrieval import (
    NO_SEQUENCE,
    NO_SEQUENCE_WHY,
    is_deterministic,
    is_retrieval,
)
from safl_bench.results.records import (
    CorruptRecordError,
    EvaluatedCell,
    MethodInfo,
    OutdatedRecordError,
    ResultRecord,
    TaskInfo,
    Timings,
    evaluated_path,
    load_evaluated,
    load_record,
    mode_result_from_evaluation,
    new_record,
    record_path,
    rescore,
    task_info,
    timed_under_load,
    write_evaluated,
    write_record,
)
from safl_bench.run.timing import pinned, time_describe
from safl_bench.sources import ROOT_OPTION
from safl_bench.sources.base import DataSource
from safl_bench.tasks import registry, spec, suite
from safl_bench.tasks.registry import runnable_spec
from safl_bench.tasks.spec import TaskSpec
from safl_bench.tasks.task import Task, prepare_tasks


@dataclass(frozen=True)
class RunOptions:
    """Everything about a run that is not the method or the task list."""

    results_dir: Path
    seed: int | None = None  # None: each task's registered seed
    force: bool = False
    kitti_root: str | None = None
    bev_root: str | None = None
    bev_resolution_m: float | None = None  # None: the source's default (0.4 m per pixel)
    bev_rot_root: str | None = None  # the rotated top views (TaskSpec.rotated); None: $SAFL_BEV_ROT_ROOT
    evaluation: EvaluationConfig = field(default_factory=default_config)
    timing_frames: int = 20
    timing_repeats: int = 5
    progress: bool = True  # bars on a terminal, else a line per finished cell (module docstring)
    share_seeds: bool = True  # time a cell once and describe its database once (`run_grid`)


@dataclass
class CellOutcome:
    """What happened to one cell."""

    task_id: str
    seed: int
    #: "computed", "reused", "rescored", "derived" (`_derived`), "relabelled" (a retrieval
    #: method's record under other sequence-matcher settings: `derive.relabel_retrieval`) or
    #: "failed"
    status: str
    path: Path
    record: ResultRecord | None = None
    message: str = ""
    method: str = ""  # the method's name
    version: str = ""  # and its version (two versions of one name are two methods)
    timed_here: bool = False  # its batch-1 timing was measured for this record (`finish_cell`)


def resolve_tasks(items: Sequence[str], *, source: str = "synth") -> list[str]:
    """Task ids from ids and suite names ('paper', 'revisit', 'all', ...), in order, no repeats.

    Suites pick the tasks on `source` ("synth", the embedded default; "kitti"; "bev", top-view
    images); the 'bev-...' suites are top-view image tasks whatever `source`. No items means the
    'paper' suite. A synthetic task on other synthetic data than this safl-bench generates (the
    synthetic tasks' v0 and v1) is a ConfigError naming the version to run (`check_data_version`).
    """
    out: list[str] = []
    for item in items or ["paper"]:
        ids = [runnable_spec(item).id] if "/" in item or item in registry else suite(item, source)
        out.extend(i for i in ids if i not in out)
    return out


def method_info(method: Method) -> MethodInfo:
    """The method part of a record: name, version and the full configuration (weights too)."""
    config = method.config()
    params = {k: v for k, v in config.items() if k not in ("name", "version")}
    return MethodInfo(name=method.name, version=str(method.version), params=params,
                      kind="retrieval" if is_retrieval(method) else "descriptor",
                      deterministic=is_deterministic(method))


def view_kind(method: Method, task: Task) -> str:
    """The views `method` reads on `task`: its `input_kind`, or top views on a source that has
    none of those when the method says it reads them too (``reads_topview``, e.g. MapClosures
    through its density-image adapter)."""
    kinds = task.source.view_kinds if task.source is not None else None
    if (kinds is not None and method.input_kind not in kinds and "topview" in kinds
            and getattr(method, "reads_topview", False)):
        return "topview"
    return method.input_kind


def recorded_settings(evaluation: EvaluationConfig, window: WindowChoice | None) -> dict[str, Any]:
    """A record's ``matcher`` field: the settings, and what the ``dip`` rule chose for the cell's
    database (`WindowChoice.to_dict`, under `window.RECORD_KEY`) when the preset uses it."""
    out = evaluation.to_dict()
    if window is not None:
        out[RECORD_KEY] = window.to_dict()
    return out


def _same_run(method: MethodInfo, task: TaskInfo, matcher: dict[str, Any], want_method: MethodInfo,
              task_fp: str, want_matcher: dict[str, Any]) -> str:
    """Why an existing record (or evaluated cell) does not hold this run ('' when it does)."""
    if method.params != want_method.params:
        return "method settings differ"
    if task.spec_fingerprint != task_fp:
        return "task definition differs"
    if not same_settings(matcher, want_matcher):  # records older than a setting read it as default
        return "matcher settings differ"
    return ""


def _seed(registered: TaskSpec, options: RunOptions) -> int:
    """The noise seed of a cell: `options.seed`, else the registered task's own."""
    return registered.seed if options.seed is None else int(options.seed)


def _existing(
    method: Method, task_id: str, options: RunOptions, log: Callable[[str], None]
) -> tuple[int, CellOutcome | EvaluatedCell | None]:
    """(seed, what already exists of the cell): its reusable record as an outcome, or the
    evaluation an interrupted parallel run left untimed, or None when it must be computed."""
    registered = runnable_spec(task_id)  # an old synthetic task's record is not reused either
    seed = _seed(registered, options)
    info = method_info(method)
    path = record_path(options.results_dir, info.name, info.version, registered.id, seed)
    if options.force:
        return seed, None
    matcher = options.evaluation.to_dict()
    if path.is_file():
        try:
            old = load_record(path)
        except CorruptRecordError as exc:
            log(f"warning: {exc}; recomputing it")
        else:
            why = _same_run(old.method, old.task, old.matcher, info, registered.fingerprint, matcher)
            if not why and old.metrics_version == METRICS_VERSION:
                return seed, CellOutcome(registered.id, seed, "reused", path, old, method=info.name,
                                         version=info.version)
            if not why:
                try:
                    new: ResultRecord | None = rescore(old)
                except OutdatedRecordError:
                    new = None
                if new is not None and new.metrics_version == METRICS_VERSION:
                    written = write_record(options.results_dir, new)
                    return seed, CellOutcome(registered.id, seed, "rescored", written, new,
                                             method=info.name, version=info.version)
                log(f"note: {path} was scored with metrics version {old.metrics_version} "
                    f"(this code: {METRICS_VERSION}) and holds no per-query outcomes; "
                    "recomputing it (its timings are kept)")
            elif why == "matcher settings differ" and old.method.kind == "retrieval":
                from safl_bench.results.derive import NotDerivableError, relabel_retrieval

                try:
                    moved = relabel_retrieval(old, matcher)
                except NotDerivableError:
                    log(f"note: {path} was made with other settings ({why}); recomputing it")
                else:
                    written = write_record(options.results_dir, moved)
                    return seed, CellOutcome(registered.id, seed, "relabelled", written, moved,
                                             method=info.name, version=info.version)
            else:
                log(f"note: {path} was made with other settings ({why}); recomputing it")
    else:
        derived = _derived(registered, seed, info, matcher, options, log)
        if derived is not None:
            return seed, derived
    pending = evaluated_path(options.results_dir, info.name, info.version, registered.id, seed)
    if pending.is_file():
        try:
            cell = load_evaluated(pending)
        except CorruptRecordError as exc:
            log(f"warning: {exc}; evaluating the cell again")
        else:
            if cell.seed == seed and cell.metrics_version == METRICS_VERSION and not _same_run(
                cell.method, cell.task, cell.matcher, info, registered.fingerprint, matcher
            ):
                return seed, cell
    return seed, None


def _derived(registered: TaskSpec, seed: int, info: MethodInfo, matcher: dict[str, Any],
             options: RunOptions, log: Callable[[str], None]) -> CellOutcome | None:
    """The cell's record derived from one of the task version it replaced, when the results
    folder holds such a record of the same run (`safl_bench.results.derive`); None otherwise."""
    from safl_bench.results.derive import NotDerivableError, derive_record
    from safl_bench.tasks.builtin import predecessor

    old_id = predecessor(registered.id)
    if old_id is None:
        return None
    old_path = record_path(options.results_dir, info.name, info.version, old_id, seed)
    if not old_path.is_file():
        return None
    try:
        old = load_record(old_path)
        from safl_bench.tasks.registry import registry

        if _same_run(old.method, old.task, old.matcher, info, registry[old_id].fingerprint, matcher):
            return None
        new = derive_record(old, registered)
    except (CorruptRecordError, NotDerivableError) as exc:
        log(f"note: {old_path} cannot be derived from ({exc}); computing the cell")
        return None
    written = write_record(options.results_dir, new)
    return CellOutcome(registered.id, seed, "derived", written, new, method=info.name,
                       version=info.version)


def _task(registered: TaskSpec, seed: int, options: RunOptions, progress: bool,
          method: Method | None = None, source: DataSource | None = None) -> Task:
    """The cell's task: the registered spec at the cell's seed, its views rendered in the
    encoding `method` reads (`Method.view_encoding`, on sources with scans; an image source's
    views are its images); on `source` when given (opened by another cell of the same data)."""
    run_spec = registered if seed == registered.seed else dataclasses.replace(registered, seed=seed)
    encoding = getattr(method, "view_encoding", None)
    if encoding and run_spec.map_config is not None and run_spec.map_config.encoding != encoding:
        from safl_bench.views.mapconfig import config_for_encoding

        run_spec = dataclasses.replace(run_spec, map_config=config_for_encoding(encoding))
    return Task.from_spec(run_spec, kitti_root=options.kitti_root, bev_root=options.bev_root,
                          bev_resolution_m=options.bev_resolution_m, progress=progress,
                          source=source, bev_rot_root=options.bev_rot_root)


def evaluate_cell(method: Method, registered: TaskSpec, seed: int, options: RunOptions,
                  progress: bool = True, where: str = "this process") -> EvaluatedCell:
    """Render (or read) the views, describe, match and score one cell; no timing, no record.
    Runs in this process or on a worker (which gets the task's spec, not its id: tasks
    registered at run time exist only in this process)."""
    return _evaluate(method, registered, _task(registered, seed, options, progress, method), options,
                     where)


def _spread(parallel: Parallel | None, n_cells: int) -> Parallel | None:
    """`parallel` when a grid has fewer cells to evaluate than it has slots (the long drive is
    one cell) and those slots are more CPUs than this machine's: then each cell is evaluated in
    this process, its describing and exact matching spread over the workers
    (`evaluate_method`'s `parallel`), instead of one worker doing the whole cell while the
    others idle. None otherwise: the cells themselves are the jobs.

    Why not on one machine: a cell in one process already uses every core (torch's and BLAS's
    threads), so spreading it over local processes adds only their start-up and the pickled
    views. Measured on the long drive (20 000 frames, 2 cores, views cached): describing and
    matching took 74 s spread over 2 local workers against 61 s in one. A Ray cluster of more
    CPUs than this machine is where it pays."""
    if parallel is None or parallel.serial or n_cells == 0:
        return None
    slots = parallel.slots()
    if n_cells >= slots or slots <= _local_cores():
        return None
    return parallel


def _local_cores() -> int:
    """The cores this process may use (`provenance.cpu_cores`)."""
    from safl_bench.results import provenance

    return provenance.cpu_cores()


def _evaluate(method: Method, registered: TaskSpec, task: Task, options: RunOptions,
              where: str, memo: DatabaseMemo | None = None,
              parallel: Parallel | None = None) -> EvaluatedCell:
    kind = view_kind(method, task)
    task.prepare([kind])
    queries, database = task.queries(kind), task.database(kind)
    try:
        evaluation = evaluate_method(
            method, method_input(method, queries), method_input(method, database),
            task.truth_for(options.evaluation), config=options.evaluation,
            revisit=task.spec.protocol == "revisit", memo=memo,
            context=task.spec.context_queries, parallel=parallel,
        )
    except NoPositivesError as exc:
        raise NoPositivesError(f"task {registered.id} (seed {task.spec.seed}): {exc}; its "
                               "ground truth leaves nothing to recall") from None
    data = task.info()
    extra = {key: data[key] for key in ("data_notes",) if key in data}
    note = input_note(method, database)
    if note is not None:
        extra["method_input"] = note
    if task.spec.map_config != registered.map_config:  # rendered in the method's encoding
        extra["views_map_config"] = task.spec.map_config
    return EvaluatedCell(
        method=method_info(method),
        task=task_info(
            registered, task.source.label if task.source is not None else task.spec.source,
            data_fingerprint=data.get("data_fingerprint"),
            n_queries=data["n_queries"], n_database=data["n_database"], **extra,
        ),
        seed=task.spec.seed,
        matcher=recorded_settings(options.evaluation, evaluation.window),
        results={m: mode_result_from_evaluation(evaluation.metrics[m], evaluation.outcomes[m])
                 for m in MODES if m in evaluation.metrics},
        describe_frames_per_s=evaluation.n_described / max(evaluation.describe_s, 1e-12),
        matcher_s=evaluation.matcher_s,
        evaluated_on=where,
        metrics_version=METRICS_VERSION,
        query_ms=None if evaluation.query_s is None else float(
            np.median(evaluation.query_s) * 1e3) if len(evaluation.query_s) else 0.0,
    )


def finish_cell(method: Method, options: RunOptions, cell: EvaluatedCell,
                task: Task | None = None, timed: tuple[int, Timings] | None = None) -> CellOutcome:
    """Time the method at batch 1 on the cell's queries (in this process, pinned to fixed CPUs,
    nothing else of the run competing for them), write the record atomically and drop the
    cell's evaluated file if a parallel run left one. `task`: the cell's task if this process
    already has it (its views are loaded), else it is opened again. `timed`: (seed, timings) of
    the same (method, task) cell timed at another seed in this run: its batch-1 figures are the
    cell's and are carried, not measured again (module docstring).

    A record of the same run that only an older metrics version made keeps its timings (the
    measures changed, not the method: `how_run` says which run timed it), unless `force`."""
    carried = None if options.force else _carried_timings(options, cell)
    if carried is not None:
        return _write(options, cell, carried)
    if timed is not None:
        at, first = timed
        return _write(options, cell, dataclasses.replace(
            first, describe_frames_per_s=cell.describe_frames_per_s, matcher_s=cell.matcher_s,
            how_run=f"{first.how_run}; the cell's timing (describe_ms_per_frame, "
                    f"peak_memory_mb), measured at seed {at}"))
    if cell.query_ms is not None:  # a retrieval method: timed per query while it answered
        return _write(options, cell, Timings(
            describe_ms_per_frame=cell.query_ms, describe_frames_per_s=cell.describe_frames_per_s,
            matcher_s=cell.matcher_s, peak_memory_mb=None, repeats=1,
            how_run=("retrieval method: describe_ms_per_frame is the median over the queries of "
                     "the method's own call per query (everything it does for one query), "
                     f"measured while evaluating on {cell.evaluated_on}; describe_frames_per_s: "
                     "queries per second of the whole retrieve call")))
    if task is None:
        task = _task(spec(cell.task.id), cell.seed, options, progress=False, method=method)
    queries = method_input(method, task.queries(method.input_kind))
    with pinned() as how_pinned:
        batch1 = time_describe(
            method, queries, batch_size=1, frames=options.timing_frames,
            repeats=options.timing_repeats, warmup=1,
        )
    where = cell.evaluated_on
    how_run = (
        f"sequential, one cell at a time in one process; timing {how_pinned}"
        if where == "this process"
        else f"evaluated on {where}; timed afterwards in the main process, one cell at a time, "
        f"{how_pinned}"
    )
    timings = Timings(
        describe_ms_per_frame=batch1.per_item_ms,
        describe_frames_per_s=cell.describe_frames_per_s,
        matcher_s=cell.matcher_s,
        peak_memory_mb=batch1.peak_rss_mb,
        repeats=options.timing_repeats,
        how_run=how_run,
        load_avg_1m=batch1.env.load_avg_1m,
    )
    return dataclasses.replace(_write(options, cell, timings), timed_here=True)


def _carried_timings(options: RunOptions, cell: EvaluatedCell) -> Timings | None:
    """The timings of the existing record of this very run (same method settings, task and
    matcher) when it is of an older metrics version (`finish_cell`), else None."""
    path = record_path(options.results_dir, cell.method.name, cell.method.version, cell.task.id,
                       cell.seed)
    try:
        old = load_record(path) if path.is_file() else None
    except CorruptRecordError:
        return None
    if old is None or old.metrics_version == METRICS_VERSION or _same_run(
            old.method, old.task, old.matcher, cell.method, cell.task.spec_fingerprint,
            cell.matcher):
        return None
    note = (f"timed by the run of {old.created} (git {old.environment.git_revision}); "
            f"rescored with metrics version {METRICS_VERSION}")
    return dataclasses.replace(old.timings, how_run=f"{old.timings.how_run}; {note}")


def _write(options: RunOptions, cell: EvaluatedCell, timings: Timings) -> CellOutcome:
    record = new_record(
        method=cell.method, task=cell.task, seed=cell.seed, matcher=cell.matcher,
        results=cell.results, timings=timings,
    )
    written = write_record(options.results_dir, record)
    evaluated_path(options.results_dir, cell.method.name, cell.method.version, cell.task.id,
                   cell.seed).unlink(missing_ok=True)
    return CellOutcome(cell.task.id, cell.seed, "computed", written, record, method=cell.method.name,
                       version=cell.method.version)


def run_cell(
    method: Method,
    task_id: str,
    options: RunOptions,
    *,
    log: Callable[[str], None] = print,
) -> CellOutcome:
    """Evaluate `method` on one task and seed in this process; write (or reuse) its record."""
    seed, existing = _existing(method, task_id, options, log)
    if isinstance(existing, CellOutcome):
        return existing
    if isinstance(existing, EvaluatedCell):  # an interrupted parallel run evaluated it
        return finish_cell(method, options, existing)
    registered = spec(task_id)
    task = _task(registered, seed, options, options.progress, method)
    return finish_cell(method, options, _evaluate(method, registered, task, options, "this process"), task)


def run_cells(
    method: Method,
    task_ids: Sequence[str],
    options: RunOptions,
    *,
    log: Callable[[str], None] | None = None,
    parallel: Parallel | None = None,
) -> list[CellOutcome]:
    """Run one method on every task: at `options.seed`, or at each task's seeds (`run_grid`)."""
    return run_grid([method], task_ids, options, log=log, parallel=parallel)


#: Runs of a cell whose method cannot be seeded (``deterministic = False``: MapClosures' RANSAC
#: draws from ``std::random_device``) on a task where nothing is random: its seeds 0..REPEATS-1
#: are repeated runs of one cell (`safl_bench.results.records.is_repeat`), so its interval covers
#: the run-to-run spread as a noisy task's covers its seeds. Three: the most the cost bound of a
#: MapClosures cell allows (issue 47: at most 3x one run).
REPEATS = 3


def cell_seeds(task: TaskSpec, seeds: Sequence[int] | None = None,
               n_seeds: int | None = None, method: Method | None = None) -> tuple[int, ...]:
    """The noise seeds to run of `task`: `seeds` when given (every task), else its first
    `n_seeds` (tasks whose queries are random; a task where nothing is random has one seed),
    else all the seeds it declares (`TaskSpec.seeds`). A `method` that cannot be seeded runs a
    task where nothing is random `REPEATS` times (`n_seeds` times when given), as seeds."""
    if seeds is not None:
        return tuple(seeds)
    declared = task.seeds
    if method is not None and not is_deterministic(method) and not task.is_random:
        return tuple(range(task.seed, task.seed + (n_seeds or REPEATS)))
    if n_seeds is None or len(declared) == 1:
        return declared
    return tuple(range(task.seed, task.seed + n_seeds))


def run_grid(
    methods: Sequence[Method],
    task_ids: Sequence[str],
    options: RunOptions,
    *,
    seeds: Sequence[int] | None = None,
    n_seeds: int | None = None,
    log: Callable[[str], None] | None = None,
    parallel: Parallel | None = None,
) -> list[CellOutcome]:
    """Run every (method, seed, task) cell, in that order; a cell that fails (bad data, a dead
    worker) is reported and the others go on. The seeds of a task: `seeds`, else
    `options.seed`, else its declared ones (`cell_seeds`, `n_seeds` of them when given).

    Serially (the default) each cell is evaluated, timed and written in turn. With `parallel`
    (local workers or Ray) all the cells of the grid are queued at once and evaluated on the
    workers, and each evaluation is kept on disk as it comes back (an interrupted run resumes
    from them); once every worker has finished, this process times the cells one by one, pinned,
    and writes the records: no timing is taken while workers compete for the cores, and only
    this process writes files.
    """
    from tqdm import tqdm

    def say(message: str) -> None:
        if log is not None:
            log(message)
        else:
            tqdm.write(message, file=sys.stderr)

    versions = [f"{m.name}@{m.version}" for m in methods]
    if len(set(versions)) < len(versions):
        raise ConfigError(f"one grid cannot hold one method twice ({', '.join(versions)}): their "
                          "records would share a path; run them into separate --results")
    if seeds is None and options.seed is not None:
        seeds = [options.seed]
    per_cell = {(m, t): cell_seeds(spec(t), seeds, n_seeds, methods[m])
                for m in range(len(methods)) for t in task_ids}
    depth = max((len(v) for v in per_cell.values()), default=0)
    cells = [
        (method, task_id, dataclasses.replace(options, seed=per_cell[(m, task_id)][j]))
        for m, method in enumerate(methods)
        for j in range(depth)
        for task_id in task_ids
        if j < len(per_cell[(m, task_id)])
    ]

    def failed(i: int, message: str) -> CellOutcome:
        method, task_id, opts = cells[i]
        seed = _seed(spec(task_id), opts)
        path = record_path(opts.results_dir, method.name, method.version, task_id, seed)
        label = task_id if len(methods) == 1 else f"{method.name} on {task_id}"
        say(f"error: {label} (seed {seed}): {message}")
        return CellOutcome(task_id, seed, "failed", path, message=message, method=method.name,
                           version=str(method.version))

    outcomes: dict[int, CellOutcome] = {}
    evaluated: dict[int, EvaluatedCell] = {}
    todo: dict[int, int] = {}  # cell -> seed
    memo: DatabaseMemo | None = {} if options.share_seeds else None
    timed: dict[tuple[int, str], tuple[int, Timings]] = {}  # (method, task) -> its first timing

    def finish(i: int, cell: EvaluatedCell, task: Task | None = None) -> CellOutcome:
        """`finish_cell`, timing each (method, task) once in this run (`share_seeds`)."""
        method, task_id, opts = cells[i]
        key = (id(method), task_id)
        outcome = finish_cell(method, opts, cell, task, timed.get(key) if memo is not None else None)
        if outcome.timed_here and outcome.record is not None:
            timed.setdefault(key, (outcome.seed, outcome.record.timings))
        return outcome

    for i, (method, task_id, opts) in enumerate(cells):
        try:
            seed, existing = _existing(method, task_id, opts, say)
        except SaflError as exc:
            outcomes[i] = failed(i, str(exc))
            continue
        if isinstance(existing, CellOutcome):
            outcomes[i] = existing
        elif isinstance(existing, EvaluatedCell):
            evaluated[i] = existing
        else:
            todo[i] = seed
    if evaluated:
        say(f"note: {len(evaluated)} cell(s) evaluated by an interrupted run are timed, not "
            "evaluated again")
    bars = options.progress and frame_progress.interactive(sys.stderr)
    lines = options.progress and not bars  # a log or CI: a line per finished cell, no bars
    if lines and todo:
        say(f"preparing the views of {len(todo)} cell(s)")
    t_views = time.perf_counter()
    with frame_progress.heartbeat(say if lines and todo else None, "preparing the views",
                                  _CellFrames.LOG_EVERY_S):
        tasks = _prepare_views(cells, todo, parallel, bars, failed, outcomes)
    if lines and todo:
        say(f"views of {len(tasks)} cell(s) ready in {time.perf_counter() - t_views:.0f} s")
    names = "/".join(m.name for m in methods)

    def line(k: int, n: int, i: int, what: str) -> None:
        method, task_id, _ = cells[i]
        label = task_id if len(methods) == 1 else f"{method.name} on {task_id}"
        say(f"[{k}/{n}] {label} seed {outcomes[i].seed if i in outcomes else todo[i]}: {what}")

    spread = _spread(parallel, len(tasks))
    if parallel is None or parallel.serial or spread is not None:
        order = sorted([*evaluated, *tasks])
        where_here = "this process" if spread is None else \
            f"this process (describing and matching spread over {spread.describe()})"
        bar = tqdm(order, desc=names, unit="cell", disable=not bars)
        for k, i in enumerate(bar, 1):
            method, task_id, opts = cells[i]
            bar.set_postfix_str(task_id)
            frames = _CellFrames(f"{task_id} frames", bars,
                                 say if options.progress and not bars else None)
            t0 = time.perf_counter()
            try:
                if i in evaluated:
                    outcomes[i] = finish(i, evaluated[i])
                else:  # popped: its views leave memory with the cell
                    task = tasks.pop(i)
                    with frames, frame_progress.reporting(frames):
                        cell = _evaluate(method, spec(task_id), task, opts, where_here, memo,
                                         spread)
                    if spread is not None:  # kept, as the workers' cells are, until timed
                        write_evaluated(options.results_dir, cell)
                    outcomes[i] = finish(i, cell, task)
            except SaflError as exc:
                outcomes[i] = failed(i, str(exc))
            if lines:
                line(k, len(order), i, f"{outcomes[i].status} in {time.perf_counter() - t0:.1f} s"
                     + (f" ({frames.done} frames)" if frames.done else ""))
        return [outcomes[i] for i in range(len(cells))]

    where = parallel.describe()
    order = sorted(tasks)  # the workers open their own tasks
    tasks.clear()
    bar = tqdm(total=len(order), desc=f"{names} ({where})", unit="cell", disable=not bars)

    back: list[int] = []  # the cells come back in the order they finish

    def keep(j: int, result: JobResult) -> None:  # in this process, as each cell comes back
        bar.update(1)
        back.append(j)
        if lines:
            line(len(back), len(order), order[j],
                 "evaluated" if result.error is None else "failed on its worker")
        if result.error is None:
            evaluated[order[j]] = result.value
            write_evaluated(options.results_dir, result.value)

    jobs = [(cells[i][0], spec(cells[i][1]), todo[i], cells[i][2], False, where) for i in order]
    try:
        results = run_jobs(evaluate_cell, jobs, parallel, on_done=keep)
    finally:
        bar.close()
    for i, result in zip(order, results, strict=True):
        if result.error is not None:
            outcomes[i] = failed(i, result.error)
    for i in sorted(evaluated):
        try:
            outcomes[i] = finish(i, evaluated[i])
        except SaflError as exc:
            outcomes[i] = failed(i, str(exc))
    return [outcomes[i] for i in range(len(cells))]


class _CellFrames:
    """The frames of one cell (`safl_bench.common.progress.FrameProgress`): counted for its
    line in a log, and shown by a bar under the grid's (removed when the cell ends) when `bar`."""

    #: In a log (no bar), a line at most this often while frames are being described.
    LOG_EVERY_S = 30.0

    def __init__(self, label: str, bar: bool, log: Callable[[str], None] | None = None) -> None:
        self.label, self.bar, self.log = label, bar, log
        self.total = self.done = 0
        self._bar: Any = None
        self._said = time.monotonic()

    def expect(self, n: int) -> None:
        self.total += n
        if self.bar and self._bar is None:
            from tqdm import tqdm

            self._bar = tqdm(total=self.total, desc=self.label, unit="frame", leave=False)
        elif self._bar is not None:
            self._bar.total = self.total
            self._bar.refresh()

    def advance(self, n: int) -> None:
        self.done += n
        if self._bar is not None:
            self._bar.update(n)
        elif self.log is not None and time.monotonic() - self._said >= self.LOG_EVERY_S:
            self._said = time.monotonic()
            share = f" ({100 * self.done / self.total:.0f} %)" if self.total else ""
            self.log(f"  {self.label}: {self.done} of {self.total} described{share}")

    def __enter__(self) -> _CellFrames:
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


def _prepare_views(
    cells: Sequence[tuple[Method, str, RunOptions]],
    todo: dict[int, int],
    parallel: Parallel | None,
    progress: bool,
    failed: Callable[[int, str], CellOutcome],
    outcomes: dict[int, CellOutcome],
) -> dict[int, Task]:
    """Open the tasks of the cells to compute and render all their views first, in as few passes
    over the scans as possible (`prepare_tasks`: the twelve paper conditions of a sequence in
    one pass, not twelve), on the workers when there are some. Cells whose task or views fail
    are recorded in `outcomes`; returns the others' tasks. In a serial run that shares across
    seeds (`RunOptions.share_seeds`) the cells of one source and sequence open it once, so its
    sequence (poses, times, the decoded images of an image source) is read once, not per seed."""
    tasks: dict[int, Task] = {}
    serial = parallel is None or parallel.serial
    sources: dict[tuple[object, ...], DataSource] = {}
    for i, seed in todo.items():
        _, task_id, opts = cells[i]
        registered = spec(task_id)
        key = (registered.source, registered.data_seed, registered.sequence, registered.rotated)
        share = serial and opts.share_seeds
        try:
            tasks[i] = _task(registered, seed, opts, progress, cells[i][0],
                             sources.get(key) if share else None)
        except SaflError as exc:
            outcomes[i] = failed(i, str(exc))
            continue
        opened = tasks[i].source
        if share and opened is not None:
            sources.setdefault(key, opened)
    _check_candidates_fit(cells, tasks)
    kinds = {i: view_kind(cells[i][0], tasks[i]) for i in tasks}
    for kind in dict.fromkeys(kinds.values()):
        members = [i for i in tasks if kinds[i] == kind]
        problems = prepare_tasks([tasks[i] for i in members], (kind,), parallel=parallel,
                                 progress=progress)
        for j, message in problems.items():
            outcomes[members[j]] = failed(members[j], message)
            tasks.pop(members[j])
    return tasks


def _check_candidates_fit(cells: Sequence[tuple[Method, str, RunOptions]],
                          tasks: dict[int, Task]) -> None:
    """A ConfigError, before any view is rendered, when ``--matcher candidates=K`` asks for more
    frames than a task's database holds: it is an option of the whole run, not a cell's fault,
    so it stops the run once (exit 2) instead of failing every cell after its views."""
    from safl_bench.matching.candidates import check_k

    for i, task in tasks.items():
        k = cells[i][2].evaluation.candidates
        if k is None:
            continue
        try:
            check_k(k, len(task.database_frames))
        except ConfigError as exc:
            raise ConfigError(f"task {task.id}: {exc}") from None


def method_labels(outcomes: Sequence[CellOutcome]) -> dict[tuple[str, str], str]:
    """The run table's label of each (method, version) of `outcomes`: the name, or `name@V`
    where the outcomes hold two versions of that name (they are two methods, never one cell)."""
    pairs = list(dict.fromkeys((o.method, o.version) for o in outcomes))
    names = [name for name, _ in pairs]
    return {(n, v): f"{n}@{v}" if names.count(n) > 1 else n for n, v in pairs}


def _cells(outcomes: Sequence[CellOutcome]) -> list[tuple[str, str, list[CellOutcome]]]:
    """(method label, task, its seeds' outcomes that have a record), in the order cells first
    appear; one cell per method version (`method_labels`)."""
    labels = method_labels(outcomes)
    cells: dict[tuple[str, str], list[CellOutcome]] = {}
    for o in outcomes:
        if o.record is not None:
            cells.setdefault((labels[(o.method, o.version)], o.task_id), []).append(o)
    return [(m, t, sorted(v, key=lambda o: o.seed)) for (m, t), v in cells.items()]


def summary_table(outcomes: Sequence[CellOutcome]) -> str:
    """A plain-text table of the headline figures per (method, task) cell over its seeds: the
    matcher preset, then recall at 100 % precision beside the measures that do not collapse on
    one confident false positive (F1max, Recall@1, AUC) of the sequence matcher, then
    single-frame matching, each as its mean over the seeds and 95 % interval over seeds and
    queries (`safl_bench.evaluation.uncertainty`); ms/frame as the median over the seeds' records and
    their range. A method column only when there are several (two versions of one name are
    two, labelled `name@V`); a failed seed gets its own row."""
    from safl_bench.evaluation.uncertainty import bootstrap
    from safl_bench.matching.presets import label
    from safl_bench.methods.training_data import (
        PARTLY_SEEN_MARK,
        SEEN_MARK,
        UNTRAINED_MARK,
        record_seen,
        record_untrained,
        seen_mark,
    )
    from safl_bench.results.records import seed_outcomes

    labels = method_labels(outcomes)
    by_method = len(labels) > 1
    lead = ("method",) if by_method else ()
    header = (*lead, "task", "seeds", "matcher", "R@100%P", "F1max", "R@1", "AUC",
              "R@100%P 1-frame", "R@1 1-frame", "ms/frame", "record")
    rows: list[tuple[str, ...]] = []
    no_interval = any_untrained = loaded = False
    marks: set[str] = set()  # the seen-in-training marks of the rows (`seen_mark`)
    for method, task_id, cell in _cells(outcomes):
        records = [o.record for o in cell if o.record is not None]
        first = records[0]
        shown: dict[str, dict[str, str]] = {}
        for mode in ("sequence", "single_frame"):
            if mode not in first.results:  # a retrieval method: no difference matrix
                shown[mode] = dict.fromkeys(("recall_at_100_precision", "f1_max", "recall_at_1",
                                             "auc"), NO_SEQUENCE)
                continue
            per_seed = seed_outcomes(records, mode)
            if per_seed is None:  # records of metrics version 1: their means only
                no_interval = True
                shown[mode] = _means_only([r.results[mode].metrics for r in records])
            else:
                iv = bootstrap(per_seed)
                shown[mode] = {"recall_at_100_precision": iv["recall_at_100_precision"].format(100),
                               "f1_max": iv["f1_max"].format(1, 3),
                               "recall_at_1": iv["recall_at_1"].format(100),
                               "auc": iv["auc"].format(1, 3)}
        # a run times a cell once and its other seeds carry that timing: one timing is shown as
        # one, a range only over distinct timings
        ms = sorted(set(r.timings.describe_ms_per_frame for r in records))
        timing = f"{float(np.median(ms)):.2f}" + (f" [{ms[0]:.2f}, {ms[-1]:.2f}]" if len(ms) > 1
                                                  else " (1 timing)" if len(records) > 1 else "")
        if any(timed_under_load(r) for r in records):
            timing += " (loaded)"
            loaded = True
        statuses = [o.status for o in cell]
        status = ", ".join(f"{s} {statuses.count(s)}" if len(statuses) > 1 else s
                           for s in dict.fromkeys(statuses))
        seq, single = shown["sequence"], shown["single_frame"]
        mark = seen_mark(record_seen(first))
        marks.add(mark)
        untrained = record_untrained(first)
        any_untrained = any_untrained or untrained
        rows.append((
            *((method,) if by_method else ()),
            task_id + mark + (UNTRAINED_MARK if untrained else ""),
            format_seed_list([o.seed for o in cell]),
            label(first.matcher), seq["recall_at_100_precision"], seq["f1_max"],
            seq["recall_at_1"], seq["auc"], single["recall_at_100_precision"],
            single["recall_at_1"], timing, status,
        ))
    for o in outcomes:
        if o.record is None:
            key = ((labels[(o.method, o.version)],) if by_method else ()) + (o.task_id, str(o.seed))
            rows.append((*key, *["—"] * (len(header) - len(key) - 1), f"failed: {o.message}"))
    widths = [max(len(r[i]) for r in (header, *rows)) for i in range(len(header))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
             for r in (header, *rows)]
    lines.insert(1, "  ".join("-" * w for w in widths))
    legend = (f"mean over the seeds [95 % interval over seeds and queries, block bootstrap]; "
              f"R@100%P, F1max, R@1: recall over the queries with a true place (metrics version "
              f"{METRICS_VERSION}; recall over correct matches is in the records); ms/frame: "
              "describing one map at batch 1, median of the cell's distinct timings [their range]; "
              "'(1 timing)': the cell was timed once, at its first seed")
    if any(NO_SEQUENCE in row for row in rows):
        legend += f"; {NO_SEQUENCE}: {NO_SEQUENCE_WHY}; its ms/frame is the method's call per query"
    extra = ["note: some records hold no per-query outcomes (metrics version 1): their cells show "
             "the mean only; `safl-bench run --force` recomputes them"] if no_interval else []
    if loaded:
        extra.append("note: (loaded): the cell's batch-1 timing was taken while the 1-minute load "
                     "average exceeded the machine's cores (other work shared the CPUs), so it "
                     "overstates the method's time; rerun with --force on an idle machine")
    old = sorted({o.record.created[:10] for o in outcomes
                  if o.record is not None and o.status != "computed"})
    if old:  # a reused record keeps the timing of the run that made it
        extra.append("note: cells not computed now (reused, rescored, derived) show the ms/frame "
                     f"timed when their record was made ({', '.join(old)}), not now; "
                     "`--force` times them again")
    if SEEN_MARK in marks:
        extra.append("note: (seen in training): the method's weights were trained on that task's "
                     "sequence; its scores measure memory, not generalisation")
    if PARTLY_SEEN_MARK in marks:
        extra.append("note: (partly seen in training): the method's weights were trained on some "
                     "of the frames that task uses (its record's seen_in_training says which); "
                     "not comparable with unseen cells")
    if any_untrained:
        extra.append(f"note:{UNTRAINED_MARK}: scored with the method's untrained (random) networks "
                     "(--weights untrained), not trained weights")
    note = zeros_note(outcomes)
    return "\n".join([*lines, legend, *extra] + ([note] if note else []))


def _means_only(metrics: Sequence[Any]) -> dict[str, str]:
    """The means over seeds of the run table's measures, for records without per-query outcomes."""
    def mean(name: str, scale: float, decimals: int) -> str:
        values = [getattr(m, name) for m in metrics]
        if any(v is None for v in values):
            return "—"
        return f"{scale * float(np.mean(values)):.{decimals}f}"

    return {"recall_at_100_precision": mean("recall_at_100_precision", 100, 1),
            "f1_max": mean("f1_max", 1, 3), "recall_at_1": mean("recall_at_1", 100, 1),
            "auc": mean("auc", 1, 3)}


def format_seed_list(seeds: Sequence[int]) -> str:
    """'0-4' for a run of consecutive seeds, else '0,3,7'."""
    ordered = sorted(seeds)
    if len(ordered) > 2 and ordered == list(range(ordered[0], ordered[-1] + 1)):
        return f"{ordered[0]}-{ordered[-1]}"
    return ",".join(map(str, ordered))


def zeros_note(outcomes: Sequence[CellOutcome]) -> str:
    """One line when recall at 100 % precision is 0 in cells whose sequence matches are mostly
    correct (Recall@1 >= 50 %): one confident false positive is enough for the zero, and
    `safl-bench explain` shows which. '' when there is no such cell."""
    cells = [o for o in outcomes if o.record is not None
             and "sequence" in o.record.results
             and o.record.results["sequence"].metrics.recall_at_100_precision == 0.0
             and (o.record.results["sequence"].metrics.recall_at_1 or 0.0) >= 0.5]
    if not cells:
        return ""
    first = cells[0]
    option = ROOT_OPTION.get(first.record.task.source_kind) if first.record is not None else None
    root = f" {option}" if option else ""
    kind = first.record.task.source_kind if first.record is not None else None
    selector = method_selector(first.method, first.version, kind) if first.version else first.method
    return (f"note: recall at 100 % precision is 0.0 in {len(cells)} record(s) whose matches are mostly "
            "correct (R@1 >= 50 %): the most confident wrong match comes before any correct one; "
            f"see which with `safl-bench explain --method {selector} --task {first.task_id}{root}`")
