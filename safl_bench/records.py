"""Result records: one JSON file per (method@version, task@version, seed).

A record holds everything needed to cite and reproduce one run: the method and its parameters,
the task and its full spec, the matcher settings, the metric values and curves of both matching
modes (SeqSLAM "sequence" matching and "single_frame" nearest neighbour), the timings, the
environment and when it was made. Files live at

    <results>/<method>@<version>/<task id, '/' -> '__'>/seed-<n>.json

and are written atomically. Loading validates every field: a file that is not valid JSON, lacks
a key, has a value of the wrong type or a non-finite number raises `CorruptRecordError` naming
the file, so callers report it and recompute instead of using it.

Every record says which definitions of the measures made it (``metrics_version``, see
`safl_bench.metrics`; records without it are version 1). Since version 2 a record also holds
each query's outcome (``results.<mode>.queries``: confidence, label, true place, candidate,
rank of the nearest true place), so `rescore` recomputes its measures under newer definitions
from what it holds. `load_records` rescores such records and reports the older ones it cannot
rescore as problems with the command that recomputes them: no table mixes versions.

A record whose method's weights were trained on its task's sequence says so in one line
(``seen_in_training``, `safl_bench.training_data`; None otherwise, and in records made before
the field existed, for which the leaderboard works it out from the weights they name).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from safl_bench.atomic import atomic_write_text
from safl_bench.errors import ConfigError, DataError
from safl_bench.fingerprint import to_jsonable
from safl_bench.metrics import METRICS_VERSION, RECALL_AT, Outcomes, evaluate_outcomes
from safl_bench.provenance import Environment, collect_environment

if TYPE_CHECKING:
    from safl_bench.metrics import Metrics as Evaluation
    from safl_bench.tasks.spec import TaskSpec

SCHEMA_VERSION = 1
#: Matching modes a record may hold; "sequence" is SeqSLAM, "single_frame" nearest neighbour.
MODES: tuple[str, ...] = ("sequence", "single_frame")
PROTOCOLS: tuple[str, ...] = ("paper", "revisit", "bevplace")
SOURCE_KINDS: tuple[str, ...] = ("synth", "kitti", "bev")
#: Curves are stored with at most this many points (plots only; metrics are exact values).
MAX_CURVE_POINTS = 200
RESULTS_ENV = "SAFL_RESULTS"

T = TypeVar("T")


class CorruptRecordError(DataError):
    """A result record file exists but cannot be used (bad JSON, missing key, wrong type)."""

    def __init__(self, path: str | os.PathLike[str], reason: str) -> None:
        self.path = Path(path)
        self.reason = reason
        super().__init__(f"corrupt result record {self.path}: {reason}")


def default_results_dir() -> Path:
    """Where records go when no --results is given: $SAFL_RESULTS, else ./results."""
    env = os.environ.get(RESULTS_ENV)
    return Path(env).expanduser() if env else Path("results")


# --------------------------------------------------------------------------------------------
# The record's parts


@dataclass(frozen=True)
class MethodInfo:
    """The method that produced a record: registry name, version and constructor parameters."""

    name: str
    version: str
    params: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class TaskInfo:
    """The task a record answers: id, version, protocol, where the data came from, full spec."""

    id: str
    version: int
    protocol: str  # "paper" | "revisit"
    sequence: str
    condition: str | None  # paper protocol: e.g. "T1R1"; revisit: None
    source_kind: str  # "synth" | "kitti"
    source_label: str  # e.g. "synthetic default (seed 0)", "KITTI"
    spec: dict[str, Any] = field(default_factory=dict)
    spec_fingerprint: str = ""


@dataclass(frozen=True)
class Metrics:
    """The measures of one matching mode, as `safl_bench.metrics` defines them (its table
    gives each one's formula and denominator). Rates are fractions in [0, 1]; None where
    undefined (auc with one class only) or not measured by the record's metrics version.

    n_positives: queries with a true place (fixed by the ground truth: the same for every method
    on a task); n_correct: correct reported matches (the ``_of_correct`` denominator); n_scored:
    queries with a candidate (the others are left out of every measure).
    """

    recall_at_100_precision: float | None
    auc: float | None
    f1_max: float | None
    extended_precision: float | None
    n_queries: int
    n_positives: int
    recall_at_1: float | None = None
    recall_at_n: dict[str, float] | None = None
    recall_at_100_precision_of_correct: float | None = None
    f1_max_of_correct: float | None = None
    extended_precision_of_correct: float | None = None
    n_scored: int | None = None
    n_correct: int | None = None
    #: the authors' reading (recall over correct matches at the first precision >= 0.99;
    #: metrics version 3), named apart from ours: `safl_bench.metrics`
    authors_recall_at_99p: float | None = None


@dataclass(frozen=True)
class QueryOutcomes:
    """Each scored query's outcome (`safl_bench.metrics.Outcomes` as JSON): what the measures
    read, so that they can be recomputed from the record. confidence: None = no match
    reported; label: 1 correct, 0 ambiguous, -1 wrong; has_true_place, has_candidate: 0 or 1;
    true_rank: rank of the nearest true place (0 = none), single-frame mode only."""

    confidence: list[float | None]
    label: list[int]
    has_true_place: list[int]
    has_candidate: list[int]
    true_rank: list[int] | None = None

    @classmethod
    def of(cls, o: Outcomes) -> QueryOutcomes:
        return cls(
            confidence=[float(c) if math.isfinite(c) else None for c in o.confidence.tolist()],
            label=[int(v) for v in o.label.tolist()],
            has_true_place=[int(v) for v in o.has_true_place.tolist()],
            has_candidate=[int(v) for v in o.has_candidate.tolist()],
            true_rank=None if o.true_rank is None else [int(v) for v in o.true_rank.tolist()],
        )

    def outcomes(self) -> Outcomes:
        return Outcomes(
            confidence=np.array([-math.inf if c is None else c for c in self.confidence],
                                dtype=np.float64),
            label=np.array(self.label, dtype=np.int8),
            has_true_place=np.array(self.has_true_place, dtype=bool),
            has_candidate=np.array(self.has_candidate, dtype=bool),
            true_rank=None if self.true_rank is None else np.array(self.true_rank, np.int64),
        )


@dataclass(frozen=True)
class PRCurve:
    """Precision against recall."""

    precision: list[float]
    recall: list[float]


@dataclass(frozen=True)
class ROCCurve:
    """True-positive rate against false-positive rate."""

    fpr: list[float]
    tpr: list[float]


@dataclass(frozen=True)
class Curves:
    """Precision-recall and ROC curves, downsampled to at most MAX_CURVE_POINTS points."""

    pr: PRCurve
    roc: ROCCurve


@dataclass(frozen=True)
class ModeResult:
    """Metrics and curves of one matching mode, and (metrics version 2 on) each query's
    outcome."""

    metrics: Metrics
    curves: Curves
    queries: QueryOutcomes | None = None


@dataclass(frozen=True)
class Timings:
    """How long describing and matching took.

    describe_ms_per_frame: median over `repeats` of describing one map at a time (batch 1);
    describe_frames_per_s: throughput when describing in batches; matcher_s: the shared
    matcher's time for the whole task; peak_memory_mb: peak resident memory (None if unknown);
    how_run: e.g. "sequential, pinned" (cells run one at a time) or "parallel, 4 workers". The
    batch-1 figures (describe_ms_per_frame, peak_memory_mb) are the (method, task) cell's: a run
    takes them once, at the first seed it computes, and the records of its other seeds carry
    them, their how_run ending "the cell's timing (...), measured at seed S" (`safl_bench.runner`).
    """

    describe_ms_per_frame: float
    describe_frames_per_s: float
    matcher_s: float
    peak_memory_mb: float | None
    repeats: int
    how_run: str


@dataclass(frozen=True)
class ResultRecord:
    """One run of one method on one task with one seed."""

    method: MethodInfo
    task: TaskInfo
    seed: int
    matcher: dict[str, Any]
    results: dict[str, ModeResult]  # keys from MODES
    timings: Timings
    environment: Environment
    created: str  # UTC, ISO 8601
    schema: int = SCHEMA_VERSION
    #: the version of `safl_bench.metrics` that scored it (a file without one is version 1)
    metrics_version: int = METRICS_VERSION
    #: one line when the method's weights were trained on this task's sequence (None: not, or
    #: unknown); `safl_bench.training_data`
    seen_in_training: str | None = None

    @property
    def key(self) -> tuple[str, str, str, int]:
        """(method, method version, task id, seed): what identifies a record."""
        return (self.method.name, self.method.version, self.task.id, self.seed)

    def to_json(self) -> dict[str, Any]:
        """Plain JSON-able dict (the file's content)."""
        return dict(to_jsonable(self))

    @classmethod
    def from_json(cls, data: Any, *, source: str | os.PathLike[str] = "<record>") -> ResultRecord:
        """Build a record from parsed JSON, validating every field.

        Raises CorruptRecordError naming `source` and the offending key.
        """
        return _parse_record(_Reader(Path(source)), data)


def utc_now() -> str:
    """The current UTC time in ISO 8601, seconds resolution (for `created`)."""
    return datetime.now(UTC).replace(microsecond=0).isoformat().replace("+00:00", "Z")


# --------------------------------------------------------------------------------------------
# Building parts from arrays


def downsample_curve(
    x: Sequence[float] | np.ndarray,
    y: Sequence[float] | np.ndarray,
    max_points: int = MAX_CURVE_POINTS,
) -> tuple[list[float], list[float]]:
    """Keep at most `max_points` points of a curve, evenly spaced by index, ends included.

    Values are rounded to 6 decimals so records stay small and byte-stable.
    """
    xa = np.asarray(x, dtype=np.float64).ravel()
    ya = np.asarray(y, dtype=np.float64).ravel()
    if xa.shape != ya.shape:
        raise ConfigError(f"curve coordinates differ in length: {xa.size} and {ya.size}")
    if not (np.all(np.isfinite(xa)) and np.all(np.isfinite(ya))):
        raise ConfigError("curve coordinates must be finite")
    if xa.size > max_points:
        keep = np.unique(np.round(np.linspace(0, xa.size - 1, max_points)).astype(np.int64))
        xa, ya = xa[keep], ya[keep]
    return [round(float(v), 6) for v in xa], [round(float(v), 6) for v in ya]


def make_mode_result(
    metrics: Metrics,
    *,
    precision: Sequence[float] | np.ndarray,
    recall: Sequence[float] | np.ndarray,
    fpr: Sequence[float] | np.ndarray,
    tpr: Sequence[float] | np.ndarray,
    queries: QueryOutcomes | None = None,
) -> ModeResult:
    """A ModeResult with the curves downsampled to MAX_CURVE_POINTS."""
    p, r = downsample_curve(precision, recall)
    f, t = downsample_curve(fpr, tpr)
    return ModeResult(
        metrics=metrics,
        curves=Curves(pr=PRCurve(precision=p, recall=r), roc=ROCCurve(fpr=f, tpr=t)),
        queries=queries,
    )


def mode_result_from_evaluation(evaluation: Evaluation,
                                outcomes: Outcomes | None = None) -> ModeResult:
    """A ModeResult from `safl_bench.metrics.evaluate`'s output (curves downsampled) and the
    per-query `outcomes` it was computed from."""
    return make_mode_result(
        Metrics(
            recall_at_100_precision=float(evaluation.recall_at_100),
            auc=None if evaluation.roc_auc is None else float(evaluation.roc_auc),
            f1_max=float(evaluation.f1_max),
            extended_precision=float(evaluation.extended_precision),
            n_queries=int(evaluation.n_queries),
            n_positives=int(evaluation.n_positive),
            recall_at_1=float(evaluation.recall_at_1),
            recall_at_n=({str(n): float(v) for n, v in evaluation.recall_at_n.items()}
                         if evaluation.recall_at_n else None),
            recall_at_100_precision_of_correct=float(evaluation.recall_at_100_of_correct),
            f1_max_of_correct=float(evaluation.f1_max_of_correct),
            extended_precision_of_correct=float(evaluation.extended_precision_of_correct),
            n_scored=int(evaluation.n_scored),
            n_correct=int(evaluation.n_correct),
            authors_recall_at_99p=float(evaluation.authors_recall_at_99p),
        ),
        precision=evaluation.precision,
        recall=evaluation.recall,
        fpr=evaluation.fpr,
        tpr=evaluation.tpr,
        queries=None if outcomes is None else QueryOutcomes.of(outcomes),
    )


class OutdatedRecordError(DataError):
    """A record scored with older definitions of the measures that holds no per-query outcomes
    to rescore it from."""


def seed_outcomes(records: Sequence[ResultRecord], mode: str) -> list[Outcomes] | None:
    """Each record's per-query outcomes in matching mode `mode` (the records: the seeds of one
    cell), for intervals and paired comparisons (`safl_bench.uncertainty`); None when a record
    holds none (metrics version 1) or lacks the mode."""
    out = []
    for record in records:
        result = record.results.get(mode)
        if result is None or result.queries is None:
            return None
        out.append(result.queries.outcomes())
    return out


def rerun_command(record: ResultRecord) -> str:
    """The command that recomputes `record` with this code."""
    from safl_bench.sources import ROOT_OPTION

    root = ROOT_OPTION.get(record.task.source_kind)
    return (f"safl-bench run --method {record.method.name}@{record.method.version} "
            f"--task {record.task.id} --seed {record.seed}{f' {root}' if root else ''} --force")


def unchanged_by_version_2(record: ResultRecord) -> bool:
    """Whether a metrics-version-1 record's measures are version 2's: version 2 changed only
    what an ambiguous match (a band between the true- and false-positive radii) and a query
    without a candidate (a time window) count as, and a task with neither is scored the same
    by both (measured: every paper- and BEVPlace-protocol cell of SAD, BiGAN and Stable-AFL
    recomputed to the same values). Such a record lacks only the measures version 2 added."""
    spec = record.task.spec
    return (record.metrics_version == 1 and spec.get("window_s") is None
            and spec.get("tp_radius_m") is not None
            and spec.get("tp_radius_m") == spec.get("fp_radius_m"))


def rescore(record: ResultRecord) -> ResultRecord:
    """`record` with its measures and curves under this code's metrics version: recomputed from
    the per-query outcomes it holds (unchanged when it already is of this version, or when it
    is a version-1 record whose measures version 2 did not change: `unchanged_by_version_2`,
    kept with its version so that it says what it lacks). Raises OutdatedRecordError for any
    other older record without outcomes."""
    if record.metrics_version == METRICS_VERSION:
        return record
    if any(mode.queries is None for mode in record.results.values()):
        if unchanged_by_version_2(record):
            return record
        raise OutdatedRecordError(
            f"scored with metrics version {record.metrics_version} (this code: "
            f"{METRICS_VERSION}) and holds no per-query outcomes to rescore; recompute it: "
            f"{rerun_command(record)}")
    results = {}
    for name, mode in record.results.items():
        assert mode.queries is not None
        o = mode.queries.outcomes()
        results[name] = mode_result_from_evaluation(
            evaluate_outcomes(o, recall_at=RECALL_AT if o.true_rank is not None else ()), o)
    return dataclasses.replace(record, results=results, metrics_version=METRICS_VERSION)


def task_info(spec: TaskSpec, source_label: str, **extra: Any) -> TaskInfo:
    """TaskInfo of a task spec run on the data source labelled `source_label`.

    `extra` (e.g. data_fingerprint=...) is stored in the spec dict beside the definition.
    """
    return TaskInfo(
        id=spec.id,
        version=int(spec.version),
        protocol=spec.protocol,
        sequence=spec.sequence,
        condition=spec.condition.name if spec.protocol == "paper" else None,
        source_kind=spec.source,
        source_label=source_label,
        spec={**spec.to_dict(), **to_jsonable(extra)},
        spec_fingerprint=spec.fingerprint,
    )


def new_record(
    *,
    method: MethodInfo,
    task: TaskInfo,
    seed: int,
    matcher: Any,
    results: dict[str, ModeResult],
    timings: Timings,
    environment: Environment | None = None,
) -> ResultRecord:
    """A record stamped now (UTC), with this process's environment unless one is given, scored
    with this code's metrics version, marked when the method's weights were trained on the
    task's sequence (`safl_bench.training_data.seen_note`).

    `matcher` may be a dict or a dataclass such as `MatcherConfig` (stored as JSON).
    """
    from safl_bench.training_data import seen_note

    matcher_json = to_jsonable(matcher)
    if not isinstance(matcher_json, dict):
        raise ConfigError(f"matcher settings must be a mapping or dataclass, got {matcher!r}")
    return ResultRecord(
        method=method,
        task=task,
        seed=int(seed),
        matcher=matcher_json,
        results=results,
        timings=timings,
        environment=environment if environment is not None else collect_environment(),
        created=utc_now(),
        metrics_version=METRICS_VERSION,
        seen_in_training=seen_note(method.params, task.source_kind, task.source_label,
                                   task.sequence),
    )


# --------------------------------------------------------------------------------------------
# Paths, writing and loading

_UNSAFE = re.compile(r"[^A-Za-z0-9._@+=-]")


def _safe(part: str) -> str:
    safe = _UNSAFE.sub("_", part.replace("/", "__"))
    if not safe or safe in (".", ".."):
        raise ConfigError(f"cannot use {part!r} in a result path")
    return safe


def record_path(
    results_dir: str | os.PathLike[str], method: str, version: str | int, task_id: str, seed: int
) -> Path:
    """Where the record of (method@version, task, seed) lives (whether or not it exists)."""
    return (
        Path(results_dir) / _safe(f"{method}@{version}") / _safe(task_id) / f"seed-{int(seed)}.json"
    )


def find_record(
    results_dir: str | os.PathLike[str], method: str, version: str | int, task_id: str, seed: int
) -> Path | None:
    """The path of the existing record of (method@version, task, seed), or None."""
    path = record_path(results_dir, method, version, task_id, seed)
    return path if path.is_file() else None


def write_record(results_dir: str | os.PathLike[str], record: ResultRecord) -> Path:
    """Validate `record` and write it atomically to its path; returns the path."""
    data = record.to_json()
    path = record_path(
        results_dir, record.method.name, record.method.version, record.task.id, record.seed
    )
    ResultRecord.from_json(data, source=path)  # refuse to write what could not be read back
    atomic_write_text(path, dumps_record(data))
    return path


_NUMBER_LIST = re.compile(r"\[\s*((?:[-+0-9.eE]+|null)(?:\s*,\s*(?:[-+0-9.eE]+|null))*)\s*\]")


def dumps_record(data: dict[str, Any]) -> str:
    """The record's file text: indented JSON, sorted keys, number lists (curves) on one line."""
    text = json.dumps(data, indent=2, sort_keys=True, allow_nan=False)
    return (
        _NUMBER_LIST.sub(
            lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]", text
        )
        + "\n"
    )


def load_record(path: str | os.PathLike[str]) -> ResultRecord:
    """Read and validate one record file. Raises CorruptRecordError naming the file."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataError(f"result record {p} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CorruptRecordError(p, f"cannot be read ({exc})") from None
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except (json.JSONDecodeError, ValueError) as exc:
        raise CorruptRecordError(p, f"not valid JSON ({exc})") from None
    return ResultRecord.from_json(data, source=p)


def load_existing(
    results_dir: str | os.PathLike[str], method: str, version: str | int, task_id: str, seed: int
) -> ResultRecord | None:
    """The stored record of (method@version, task, seed), None if absent.

    Raises CorruptRecordError if the file is corrupt or describes another run than its path says.
    """
    path = find_record(results_dir, method, version, task_id, seed)
    if path is None:
        return None
    record = load_record(path)
    if record.key != (method, str(version), task_id, int(seed)):
        raise CorruptRecordError(
            path, f"holds {record.key}, not {(method, str(version), task_id, seed)}"
        )
    return record


@dataclass(frozen=True)
class Problem:
    """A record file that could not be used, and why."""

    path: Path
    reason: str

    def __str__(self) -> str:
        return f"{self.path}: {self.reason}"


def load_records(results_dir: str | os.PathLike[str]) -> tuple[list[ResultRecord], list[Problem]]:
    """All valid records under `results_dir` (sorted by key), and the files that were not.

    Corrupt files are skipped and listed as problems by name; so are files whose run another
    file already holds (the newer `created` wins), and records of an older metrics version that
    cannot be rescored (`rescore`; the problem says what to run). Rescorable ones are rescored. Temporary files of interrupted writes
    (dot-files) are ignored. A missing directory gives no records and no problems.
    """
    root = Path(results_dir)
    by_key: dict[tuple[str, str, str, int], tuple[ResultRecord, Path]] = {}
    problems: list[Problem] = []
    if not root.is_dir():
        return [], []
    for path in sorted(root.rglob("seed-*.json")):
        if path.name.startswith("."):
            continue
        try:
            record = load_record(path)
        except CorruptRecordError as exc:
            problems.append(Problem(path, exc.reason))
            continue
        try:
            record = rescore(record)
        except OutdatedRecordError as exc:
            problems.append(Problem(path, str(exc)))
            continue
        previous = by_key.get(record.key)
        if previous is not None:
            older, newer = sorted(
                [previous, (record, path)], key=lambda rp: (rp[0].created, str(rp[1]))
            )
            problems.append(Problem(older[1], f"duplicate of {newer[1]} (the newer one is used)"))
            by_key[record.key] = newer
        else:
            by_key[record.key] = (record, path)
    records = [by_key[k][0] for k in sorted(by_key)]
    return records, sorted(problems, key=lambda p: str(p.path))


# --------------------------------------------------------------------------------------------
# Cells evaluated but not yet timed

#: Suffix of an evaluated cell's file beside its record's path (not a record: `load_records`
#: reads only seed-*.json).
EVALUATED_SUFFIX = ".evaluated"


@dataclass(frozen=True)
class EvaluatedCell:
    """A record's content before its timings: what a worker computed for one cell. A parallel
    run keeps it on disk until the cell is timed, so an interrupted run does not evaluate the
    cell again."""

    method: MethodInfo
    task: TaskInfo
    seed: int
    matcher: dict[str, Any]
    results: dict[str, ModeResult]
    describe_frames_per_s: float  # batched throughput measured while evaluating
    matcher_s: float
    evaluated_on: str  # "this process", "2 local worker processes", "Ray cluster (auto)"
    metrics_version: int = METRICS_VERSION


def evaluated_path(
    results_dir: str | os.PathLike[str], method: str, version: str | int, task_id: str, seed: int
) -> Path:
    """Where the evaluated-but-untimed cell (method@version, task, seed) is kept."""
    path = record_path(results_dir, method, version, task_id, seed)
    return path.with_name(path.name + EVALUATED_SUFFIX)


def write_evaluated(results_dir: str | os.PathLike[str], cell: EvaluatedCell) -> Path:
    """Write `cell` atomically beside its future record; returns the path."""
    path = evaluated_path(results_dir, cell.method.name, cell.method.version, cell.task.id, cell.seed)
    data = dict(to_jsonable(cell))
    _parse_evaluated(_Reader(path), data)  # refuse to write what could not be read back
    atomic_write_text(path, dumps_record(data))
    return path


def load_evaluated(path: str | os.PathLike[str]) -> EvaluatedCell:
    """Read and validate an evaluated cell. Raises CorruptRecordError naming the file."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"), parse_constant=_reject_constant)
    except FileNotFoundError:
        raise DataError(f"evaluated cell {p} does not exist") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise CorruptRecordError(p, f"cannot be read as JSON ({exc})") from None
    return _parse_evaluated(_Reader(p), data)


# --------------------------------------------------------------------------------------------
# Validation


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not allowed")


class _Reader:
    """Typed access to parsed JSON that names the file and key path in every error."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, where: str, message: str) -> CorruptRecordError:
        return CorruptRecordError(self.path, f"{where}: {message}" if where else message)

    def obj(self, data: Any, where: str) -> dict[str, Any]:
        if not isinstance(data, dict):
            raise self.fail(where, f"expected an object, got {type(data).__name__}")
        return data

    def get(self, data: dict[str, Any], key: str, where: str, check: Callable[[Any, str], T]) -> T:
        sub = f"{where}.{key}" if where else key
        if key not in data:
            raise self.fail(sub, "missing")
        return check(data[key], sub)

    def str_(self, value: Any, where: str) -> str:
        if not isinstance(value, str):
            raise self.fail(where, f"expected a string, got {type(value).__name__}")
        return value

    def nonempty_str(self, value: Any, where: str) -> str:
        text = self.str_(value, where)
        if not text:
            raise self.fail(where, "must not be empty")
        return text

    def opt_str(self, value: Any, where: str) -> str | None:
        return None if value is None else self.str_(value, where)

    def int_(self, value: Any, where: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(where, f"expected an integer, got {type(value).__name__}")
        if value < 0:
            raise self.fail(where, f"must be >= 0, got {value}")
        return value

    def opt_int(self, value: Any, where: str) -> int | None:
        return None if value is None else self.int_(value, where)

    def float_(self, value: Any, where: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(where, f"expected a number, got {type(value).__name__}")
        if not math.isfinite(value) or value < 0:
            raise self.fail(where, f"must be a finite number >= 0, got {value}")
        return float(value)

    def opt_float(self, value: Any, where: str) -> float | None:
        return None if value is None else self.float_(value, where)

    def rate(self, value: Any, where: str) -> float | None:
        if value is None:
            return None
        number = self.float_(value, where)
        if number > 1.0:
            raise self.fail(where, f"must be a fraction in [0, 1], got {number}")
        return number

    def dict_(self, value: Any, where: str) -> dict[str, Any]:
        return self.obj(value, where)

    def rates(self, value: Any, where: str) -> dict[str, float] | None:
        """None, or {"N": fraction} with N a positive integer."""
        if value is None:
            return None
        out: dict[str, float] = {}
        for key, rate in self.obj(value, where).items():
            number = self.rate(rate, f"{where}.{key}")
            if not key.isdigit() or int(key) < 1 or number is None:
                raise self.fail(f"{where}.{key}", "expected a positive integer N and a fraction")
            out[key] = number
        return out

    def floats(self, value: Any, where: str) -> list[float]:
        if not isinstance(value, list):
            raise self.fail(where, f"expected a list, got {type(value).__name__}")
        out = []
        for i, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise self.fail(f"{where}[{i}]", f"expected a finite number, got {v!r}")
            out.append(float(v))
        return out

    def str_map(self, value: Any, where: str) -> dict[str, str]:
        data = self.obj(value, where)
        return {k: self.get(data, k, where, self.str_) for k in data}

    def one_of(self, options: tuple[str, ...]) -> Callable[[Any, str], str]:
        def check(value: Any, where: str) -> str:
            text = self.str_(value, where)
            if text not in options:
                raise self.fail(where, f"must be one of {', '.join(options)}, got {text!r}")
            return text

        return check


def _parse_method(r: _Reader, data: Any) -> MethodInfo:
    d = r.obj(data, "method")
    return MethodInfo(
        name=r.get(d, "name", "method", r.nonempty_str),
        version=r.get(d, "version", "method", r.nonempty_str),
        params=r.get(d, "params", "method", r.dict_),
    )


def _parse_task(r: _Reader, data: Any) -> TaskInfo:
    d = r.obj(data, "task")
    return TaskInfo(
        id=r.get(d, "id", "task", r.nonempty_str),
        version=r.get(d, "version", "task", r.int_),
        protocol=r.get(d, "protocol", "task", r.one_of(PROTOCOLS)),
        sequence=r.get(d, "sequence", "task", r.nonempty_str),
        condition=r.get(d, "condition", "task", r.opt_str),
        source_kind=r.get(d, "source_kind", "task", r.one_of(SOURCE_KINDS)),
        source_label=r.get(d, "source_label", "task", r.nonempty_str),
        spec=r.get(d, "spec", "task", r.dict_),
        spec_fingerprint=r.get(d, "spec_fingerprint", "task", r.str_),
    )


def _parse_mode(r: _Reader, data: Any, where: str) -> ModeResult:
    d = r.obj(data, where)
    m = r.get(d, "metrics", where, r.dict_)
    mw = f"{where}.metrics"
    metrics = Metrics(
        recall_at_100_precision=r.get(m, "recall_at_100_precision", mw, r.rate),
        auc=r.get(m, "auc", mw, r.rate),
        f1_max=r.get(m, "f1_max", mw, r.rate),
        extended_precision=r.get(m, "extended_precision", mw, r.rate),
        n_queries=r.get(m, "n_queries", mw, r.int_),
        n_positives=r.get(m, "n_positives", mw, r.int_),
        recall_at_1=r.rate(m.get("recall_at_1"), f"{mw}.recall_at_1"),
        recall_at_n=r.rates(m.get("recall_at_n"), f"{mw}.recall_at_n"),
        **{key: r.rate(m.get(key), f"{mw}.{key}") for key in (
            "recall_at_100_precision_of_correct", "f1_max_of_correct",
            "extended_precision_of_correct", "authors_recall_at_99p")},
        n_scored=r.opt_int(m.get("n_scored"), f"{mw}.n_scored"),
        n_correct=r.opt_int(m.get("n_correct"), f"{mw}.n_correct"),
    )
    c = r.get(d, "curves", where, r.dict_)
    cw = f"{where}.curves"
    pr_raw = r.get(c, "pr", cw, r.dict_)
    roc_raw = r.get(c, "roc", cw, r.dict_)
    pr = PRCurve(
        precision=r.get(pr_raw, "precision", f"{cw}.pr", r.floats),
        recall=r.get(pr_raw, "recall", f"{cw}.pr", r.floats),
    )
    roc = ROCCurve(
        fpr=r.get(roc_raw, "fpr", f"{cw}.roc", r.floats),
        tpr=r.get(roc_raw, "tpr", f"{cw}.roc", r.floats),
    )
    if len(pr.precision) != len(pr.recall):
        raise r.fail(f"{cw}.pr", "precision and recall differ in length")
    if len(roc.fpr) != len(roc.tpr):
        raise r.fail(f"{cw}.roc", "fpr and tpr differ in length")
    queries = None if d.get("queries") is None else _parse_queries(r, d["queries"], f"{where}.queries")
    return ModeResult(metrics=metrics, curves=Curves(pr=pr, roc=roc), queries=queries)


def _parse_queries(r: _Reader, data: Any, where: str) -> QueryOutcomes:
    d = r.obj(data, where)

    def ints(key: str, allowed: tuple[int, ...] | None) -> list[int]:
        values = r.get(d, key, where, lambda v, w: v)
        if not isinstance(values, list) or any(
                isinstance(v, bool) or not isinstance(v, int)
                or (v not in allowed if allowed else v < 0) for v in values):
            raise r.fail(f"{where}.{key}", "expected a list of integers"
                         + (f" in {allowed}" if allowed else " >= 0"))
        return values

    conf = r.get(d, "confidence", where, lambda v, w: v)
    if not isinstance(conf, list) or any(
            c is not None and (isinstance(c, bool) or not isinstance(c, int | float)
                               or not math.isfinite(c)) for c in conf):
        raise r.fail(f"{where}.confidence", "expected a list of finite numbers or null")
    out = QueryOutcomes(
        confidence=[None if c is None else float(c) for c in conf],
        label=ints("label", (-1, 0, 1)),
        has_true_place=ints("has_true_place", (0, 1)),
        has_candidate=ints("has_candidate", (0, 1)),
        true_rank=None if d.get("true_rank") is None else ints("true_rank", None),
    )
    lengths = {len(out.confidence), len(out.label), len(out.has_true_place),
               len(out.has_candidate)} | ({len(out.true_rank)} if out.true_rank is not None else set())
    if len(lengths) != 1:
        raise r.fail(where, "its per-query lists differ in length")
    return out


def _parse_timings(r: _Reader, data: Any) -> Timings:
    d = r.obj(data, "timings")
    return Timings(
        describe_ms_per_frame=r.get(d, "describe_ms_per_frame", "timings", r.float_),
        describe_frames_per_s=r.get(d, "describe_frames_per_s", "timings", r.float_),
        matcher_s=r.get(d, "matcher_s", "timings", r.float_),
        peak_memory_mb=r.get(d, "peak_memory_mb", "timings", r.opt_float),
        repeats=r.get(d, "repeats", "timings", r.int_),
        how_run=r.get(d, "how_run", "timings", r.str_),
    )


def _parse_environment(r: _Reader, data: Any) -> Environment:
    d = r.obj(data, "environment")
    return Environment(
        python=r.get(d, "python", "environment", r.str_),
        libraries=r.get(d, "libraries", "environment", r.str_map),
        platform=r.get(d, "platform", "environment", r.str_),
        cpu_model=r.get(d, "cpu_model", "environment", r.str_),
        cpu_cores=r.get(d, "cpu_cores", "environment", r.int_),
        torch_threads=r.get(d, "torch_threads", "environment", r.opt_int),
        git_revision=r.get(d, "git_revision", "environment", r.str_),
    )


def _parse_record(r: _Reader, data: Any) -> ResultRecord:
    d = r.obj(data, "")
    schema = r.get(d, "schema", "", r.int_)
    if schema != SCHEMA_VERSION:
        raise r.fail("schema", f"version {schema} is not the supported {SCHEMA_VERSION}")
    results = _parse_results(r, d)
    created = r.get(d, "created", "", r.nonempty_str)
    try:
        datetime.fromisoformat(created)
    except ValueError:
        raise r.fail("created", f"not an ISO 8601 time: {created!r}") from None
    return ResultRecord(
        method=_parse_method(r, r.get(d, "method", "", lambda v, w: v)),
        task=_parse_task(r, r.get(d, "task", "", lambda v, w: v)),
        seed=r.get(d, "seed", "", r.int_),
        matcher=r.get(d, "matcher", "", r.dict_),
        results=results,
        timings=_parse_timings(r, r.get(d, "timings", "", lambda v, w: v)),
        environment=_parse_environment(r, r.get(d, "environment", "", lambda v, w: v)),
        created=created,
        schema=schema,
        metrics_version=_metrics_version(r, d, ""),
        seen_in_training=r.opt_str(d.get("seen_in_training"), "seen_in_training"),
    )


def _metrics_version(r: _Reader, d: dict[str, Any], where: str) -> int:
    """The record's metrics version (1 when absent: records from before it was stored)."""
    key = f"{where}.metrics_version" if where else "metrics_version"
    version = r.int_(d.get("metrics_version", 1), key)
    if not 1 <= version <= METRICS_VERSION:
        raise r.fail(key, f"version {version} is newer than this code's {METRICS_VERSION}: "
                          "upgrade safl-bench to read it")
    return version


def _parse_results(r: _Reader, d: dict[str, Any]) -> dict[str, ModeResult]:
    raw_results = r.get(d, "results", "", r.dict_)
    if not raw_results:
        raise r.fail("results", "holds no matching mode")
    results = {}
    for mode in sorted(raw_results):
        if mode not in MODES:
            raise r.fail(f"results.{mode}", f"unknown matching mode (known: {', '.join(MODES)})")
        results[mode] = _parse_mode(r, raw_results[mode], f"results.{mode}")
    return results


def _parse_evaluated(r: _Reader, data: Any) -> EvaluatedCell:
    d = r.obj(data, "")
    return EvaluatedCell(
        method=_parse_method(r, r.get(d, "method", "", lambda v, w: v)),
        task=_parse_task(r, r.get(d, "task", "", lambda v, w: v)),
        seed=r.get(d, "seed", "", r.int_),
        matcher=r.get(d, "matcher", "", r.dict_),
        results=_parse_results(r, d),
        describe_frames_per_s=r.get(d, "describe_frames_per_s", "", r.float_),
        matcher_s=r.get(d, "matcher_s", "", r.float_),
        evaluated_on=r.get(d, "evaluated_on", "", r.nonempty_str),
        metrics_version=_metrics_version(r, d, ""),
    )

