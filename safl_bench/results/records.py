"""Result records: one JSON file per (method@version, task@version, seed).

A record holds everything needed to cite and reproduce one run: the method and its parameters,
the task and its full spec, the matcher settings, the metric values and curves of both matching
modes (SeqSLAM "sequence" matching and "single_frame" nearest neighbour), the timings, the
environment and when it was made. Files live at

    <results>/<method>@<version>/<task id, '/' -> '__'>/seed-<n>.json

and are written atomically. The record's parts are dataclasses whose field types (`fields`) carry
every rule a file must keep; pydantic validates a file against them (`ResultRecord.from_json`)
and publishes them as a JSON Schema (`record_schema`, ``safl-bench records schema``,
docs/reference/record.schema.json). A file that is not valid JSON, lacks a key, has a value of
the wrong type, out of range or non-finite raises `CorruptRecordError` naming the file and the
field in one line, so callers report it and recompute instead of using it.

Every record says which definitions of the measures made it (``metrics_version``, see
`safl_bench.evaluation.metrics`; records without it are version 1). Since version 2 a record also holds
each query's outcome (``results.<mode>.queries``: confidence, label, true place, candidate,
rank of the nearest true place), so `rescore` recomputes its measures under newer definitions
from what it holds. `load_records` rescores such records and reports the older ones it cannot
rescore as problems with the command that recomputes them: no table mixes versions.

A record whose method's weights were trained on its task's sequence says so in one line
(``seen_in_training``, `safl_bench.methods.training_data`; None otherwise, and in records made before
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
from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Literal, cast, get_args

import numpy as np
from pydantic import AfterValidator, BeforeValidator, ConfigDict, Field, Strict, TypeAdapter
from pydantic import ValidationError as _ValidationError

from safl_bench.common.atomic import atomic_write_text
from safl_bench.common.fingerprint import to_jsonable
from safl_bench.errors import ConfigError, DataError
from safl_bench.evaluation.metrics import METRICS_VERSION, RECALL_AT, Outcomes, evaluate_outcomes
from safl_bench.results.fields import RECORD_CONFIG, Amount, Count, Name, Number, Rate, Text
from safl_bench.results.provenance import Environment, collect_environment

if TYPE_CHECKING:
    from safl_bench.evaluation.metrics import Metrics as Evaluation
    from safl_bench.tasks.spec import TaskSpec

SCHEMA_VERSION = 1
#: Matching modes a record may hold; "sequence" is SeqSLAM, "single_frame" nearest neighbour.
MODES: tuple[str, ...] = ("sequence", "single_frame")
ProtocolName = Literal["paper", "revisit", "bevplace"]
SourceKind = Literal["synth", "kitti", "bev"]
PROTOCOLS: tuple[str, ...] = get_args(ProtocolName)
SOURCE_KINDS: tuple[str, ...] = get_args(SourceKind)
#: Curves are stored with at most this many points (plots only; metrics are exact values).
MAX_CURVE_POINTS = 200
RESULTS_ENV = "SAFL_RESULTS"


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


# --------------------------------------------------------------------------------------------
# The rules a file must keep beyond its fields' types (pydantic runs them; messages as printed)


def _same_length(a: str, b: str) -> Any:
    def check(curve: Any) -> Any:
        if len(getattr(curve, a)) != len(getattr(curve, b)):
            raise ValueError(f"{a} and {b} differ in length")
        return curve

    return check


def _one_length(queries: QueryOutcomes) -> QueryOutcomes:
    lengths = {len(queries.confidence), len(queries.label), len(queries.has_true_place),
               len(queries.has_candidate)}
    if queries.true_rank is not None:
        lengths.add(len(queries.true_rank))
    if queries.match is not None:
        lengths.add(len(queries.match))
    if queries.relative_pose is not None:
        lengths.add(len(queries.relative_pose))
    if len(lengths) != 1:
        raise ValueError("its per-query lists differ in length")
    return queries


def _iso_time(text: str) -> str:
    try:
        datetime.fromisoformat(text)
    except ValueError:
        raise ValueError(f"not an ISO 8601 time: {text!r}") from None
    return text


def _supported_schema(version: int) -> int:
    if version != SCHEMA_VERSION:
        raise ValueError(f"version {version} is not the supported {SCHEMA_VERSION}")
    return version


def _known_metrics_version(version: int) -> int:
    if not 1 <= version <= METRICS_VERSION:
        raise ValueError(f"version {version} is newer than this code's {METRICS_VERSION}: "
                         "upgrade safl-bench to read it")
    return version


def _known_modes(results: Any) -> Any:
    if isinstance(results, dict):
        if not results:
            raise ValueError("holds no matching mode")
        unknown = sorted(set(results) - set(MODES))
        if unknown:
            raise ValueError(f"unknown matching mode {unknown[0]!r} (known: {', '.join(MODES)})")
        return dict(sorted(results.items()))
    return results


#: `metrics_version`: 1 (records from before it was stored) up to this code's.
MetricsVersion = Annotated[int, Strict(), Field(ge=1), AfterValidator(_known_metrics_version)]


@dataclass(frozen=True)
class MethodInfo:
    """The method that produced a record: registry name, version and constructor parameters."""

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    name: Name
    version: Name
    params: dict[str, Any] = field(default_factory=dict)
    #: "descriptor" (describe + distance) or "retrieval" (ranked, verified candidates: no
    #: difference matrix, so no sequence-matcher result; `safl_bench.methods.retrieval`)
    kind: Literal["descriptor", "retrieval"] = "descriptor"
    #: False for a method that cannot be seeded (its answers vary between identical runs:
    #: MapClosures' RANSAC draws from std::random_device). On a task where nothing is random
    #: such a method's seeds are repeated runs of one cell (`is_repeat`); True in records
    #: written before the field existed.
    deterministic: bool = True


@dataclass(frozen=True)
class TaskInfo:
    """The task a record answers: id, version, protocol, where the data came from, full spec."""

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    id: Name
    version: Count
    protocol: ProtocolName
    sequence: Name
    condition: Text | None  # paper protocol: e.g. "T1R1"; revisit: None
    source_kind: SourceKind
    source_label: Name  # e.g. "synthetic default (seed 0)", "KITTI"
    spec: dict[str, Any] = field(default_factory=dict)
    spec_fingerprint: Text = ""


@dataclass(frozen=True)
class Metrics:
    """The measures of one matching mode, as `safl_bench.evaluation.metrics` defines them (its table
    gives each one's formula and denominator). Rates are fractions in [0, 1]; None where
    undefined (auc with one class only) or not measured by the record's metrics version.

    n_positives: queries with a true place (fixed by the ground truth: the same for every method
    on a task); n_correct: correct reported matches (the ``_of_correct`` denominator); n_scored:
    queries with a candidate (the others are left out of every measure).
    """

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    recall_at_100_precision: Rate | None
    auc: Rate | None
    f1_max: Rate | None
    extended_precision: Rate | None
    n_queries: Count
    n_positives: Count
    recall_at_1: Rate | None = None
    #: Recall@N by N (a positive integer, as a string: JSON keys are strings)
    recall_at_n: dict[Annotated[str, Strict(), Field(pattern=r"^[1-9][0-9]*$")], Rate] | None = None
    recall_at_100_precision_of_correct: Rate | None = None
    f1_max_of_correct: Rate | None = None
    extended_precision_of_correct: Rate | None = None
    n_scored: Count | None = None
    n_correct: Count | None = None
    #: the authors' reading (recall over correct matches at the first precision >= 0.99;
    #: metrics version 3), named apart from ours: `safl_bench.evaluation.metrics`
    authors_recall_at_99p: Rate | None = None


@dataclass(frozen=True)
class QueryOutcomes:
    """Each scored query's outcome (`safl_bench.evaluation.metrics.Outcomes` as JSON): what the measures
    read, so that they can be recomputed from the record. confidence: None = no match
    reported; label: 1 correct, 0 ambiguous, -1 wrong; has_true_place, has_candidate: 0 or 1;
    true_rank: rank of the nearest true place (0 = none), single-frame mode only; match: the
    database frame each query matched (-1 = none; what the loop-closure stage, `safl_bench.slam`,
    reads), absent from records made before it was stored; relative_pose: the method's own
    estimate of its matched frame's pose in the query's frame, [x m, y m, yaw rad] (T_query^-1
    T_match in SE(2)), null where it gives none; absent for methods that estimate no pose."""

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    confidence: list[Number | None]
    label: list[Annotated[int, Strict(), Field(ge=-1, le=1)]]
    has_true_place: list[Annotated[int, Strict(), Field(ge=0, le=1)]]
    has_candidate: list[Annotated[int, Strict(), Field(ge=0, le=1)]]
    true_rank: list[Count] | None = None
    match: list[Annotated[int, Strict(), Field(ge=-1)]] | None = None
    relative_pose: list[Annotated[list[Number], Field(min_length=3, max_length=3)] | None] | None = None

    @classmethod
    def of(cls, o: Outcomes) -> QueryOutcomes:
        return cls(
            confidence=[float(c) if math.isfinite(c) else None for c in o.confidence.tolist()],
            label=[int(v) for v in o.label.tolist()],
            has_true_place=[int(v) for v in o.has_true_place.tolist()],
            has_candidate=[int(v) for v in o.has_candidate.tolist()],
            true_rank=None if o.true_rank is None else [int(v) for v in o.true_rank.tolist()],
            match=None if o.match is None else [int(v) for v in o.match.tolist()],
            relative_pose=None if o.relative_pose is None else [
                None if math.isnan(row[0]) else [float(v) for v in row]
                for row in o.relative_pose.tolist()],
        )

    def outcomes(self) -> Outcomes:
        return Outcomes(
            confidence=np.array([-math.inf if c is None else c for c in self.confidence],
                                dtype=np.float64),
            label=np.array(self.label, dtype=np.int8),
            has_true_place=np.array(self.has_true_place, dtype=bool),
            has_candidate=np.array(self.has_candidate, dtype=bool),
            true_rank=None if self.true_rank is None else np.array(self.true_rank, np.int64),
            match=None if self.match is None else np.array(self.match, np.int64),
            relative_pose=None if self.relative_pose is None else np.array(
                [[math.nan] * 3 if p is None else p for p in self.relative_pose], np.float64
            ).reshape(-1, 3),
        )


@dataclass(frozen=True)
class PRCurve:
    """Precision against recall."""

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    precision: list[Number]
    recall: list[Number]


@dataclass(frozen=True)
class ROCCurve:
    """True-positive rate against false-positive rate."""

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    fpr: list[Number]
    tpr: list[Number]


@dataclass(frozen=True)
class Curves:
    """Precision-recall and ROC curves, downsampled to at most MAX_CURVE_POINTS points."""

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    pr: Annotated[PRCurve, AfterValidator(_same_length("precision", "recall"))]
    roc: Annotated[ROCCurve, AfterValidator(_same_length("fpr", "tpr"))]


@dataclass(frozen=True)
class ModeResult:
    """Metrics and curves of one matching mode, and (metrics version 2 on) each query's
    outcome."""

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    metrics: Metrics
    curves: Curves
    queries: Annotated[QueryOutcomes, AfterValidator(_one_length)] | None = None


#: The matching modes of a record (keys from MODES, read in sorted order).
ModeResults = Annotated[dict[str, ModeResult], BeforeValidator(_known_modes)]


@dataclass(frozen=True)
class Timings:
    """How long describing and matching took.

    describe_ms_per_frame: median over `repeats` of describing one map at a time (batch 1);
    describe_frames_per_s: throughput when describing in batches; matcher_s: the shared
    matcher's time for the whole task; peak_memory_mb: peak resident memory (None if unknown);
    how_run: e.g. "sequential, pinned" (cells run one at a time) or "parallel, 4 workers". The
    batch-1 figures (describe_ms_per_frame, peak_memory_mb) are the (method, task) cell's: a run
    takes them once, at the first seed it computes, and the records of its other seeds carry
    them, their how_run ending "the cell's timing (...), measured at seed S" (`safl_bench.run.runner`).
    """

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    describe_ms_per_frame: Amount
    describe_frames_per_s: Amount
    matcher_s: Amount
    peak_memory_mb: Amount | None
    repeats: Count
    how_run: Text
    #: the 1-minute load average at the end of the batch-1 timing (None: not measured, as in
    #: records made before it was kept); above the host's usable cores (`Environment.cpu_cores`)
    #: other work shared the CPUs while it was timed (`timed_under_load`)
    load_avg_1m: Amount | None = None


def timed_under_load(record: ResultRecord) -> bool | None:
    """Whether the record's batch-1 timing was taken while more threads wanted the CPUs than
    the host has usable cores (its 1-minute load average above `Environment.cpu_cores`): then
    it is slower than the method, by how much is not known. None when the record does not say."""
    load = record.timings.load_avg_1m
    cores = record.environment.cpu_cores
    if load is None or not cores:
        return None
    return bool(load > cores)


@dataclass(frozen=True)
class Derivation:
    """Where a derived record's matches come from (`safl_bench.results.derive`): the record of
    the superseded task version `task` (made at `created`) whose per-query outcomes it keeps,
    with the queries the new version leaves out of the measures dropped and every measure
    recomputed; `note` says so in one line."""

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    task: Name
    created: Annotated[Name, AfterValidator(_iso_time)]
    note: Text


@dataclass(frozen=True)
class ResultRecord:
    """One run of one method on one task with one seed."""

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    method: MethodInfo
    task: TaskInfo
    seed: Count
    matcher: dict[str, Any]
    results: ModeResults  # keys from MODES
    timings: Timings
    environment: Environment
    created: Annotated[Name, AfterValidator(_iso_time)]  # UTC, ISO 8601
    schema: Annotated[Count, AfterValidator(_supported_schema)] = SCHEMA_VERSION
    #: the version of `safl_bench.evaluation.metrics` that scored it (a file without one is version 1)
    metrics_version: MetricsVersion = METRICS_VERSION
    #: one line when the method's weights were trained on this task's sequence (None: not, or
    #: unknown); `safl_bench.methods.training_data`
    seen_in_training: Text | None = None
    #: set when the record was derived from one of a superseded task version instead of
    #: computed (`safl_bench.results.derive`); None for a computed record
    derived_from: Derivation | None = None

    @property
    def key(self) -> tuple[str, str, str, int]:
        """(method, method version, task id, seed): what identifies a record."""
        return (self.method.name, self.method.version, self.task.id, self.seed)

    def to_json(self) -> dict[str, Any]:
        """Plain JSON-able dict (the file's content)."""
        return dict(to_jsonable(self))

    @classmethod
    def from_json(cls, data: Any, *, source: str | os.PathLike[str] = "<record>") -> ResultRecord:
        """Build a record from parsed JSON, validating every field (`record_schema`).

        Raises CorruptRecordError naming `source` and the offending field.
        """
        return _validate(_RECORD, data, Path(source))


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
    xa: np.ndarray = np.asarray(x, dtype=np.float64).ravel()
    ya: np.ndarray = np.asarray(y, dtype=np.float64).ravel()
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
    """A ModeResult from `safl_bench.evaluation.metrics.evaluate`'s output (curves downsampled) and the
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
    cell), for intervals and paired comparisons (`safl_bench.evaluation.uncertainty`); None when a record
    holds none (metrics version 1) or lacks the mode."""
    out = []
    for record in records:
        result = record.results.get(mode)
        if result is None or result.queries is None:
            return None
        out.append(result.queries.outcomes())
    return out


def is_repeat(record: ResultRecord) -> bool:
    """Whether `record` is a repeated run of a cell rather than a cell of its own: a method that
    cannot be seeded (`MethodInfo.deterministic` false), at a seed other than its task's, on a
    task where nothing is random (a paper-protocol T0R0 task, the revisit and BEVPlace
    protocols). Such seeds change no query; the runner makes them for such a method
    (`safl_bench.run.runner.REPEATS`), so the tables read them as runs of the task seed's cell
    and the loop-closure stage scores the first run alone. A seedable method run there at other
    seeds (asked for with --seed) answers the same at each: those records stay seeds."""
    from safl_bench.views.noise import Condition

    task = record.task
    random = task.protocol == "paper" and not Condition.parse(task.spec.get("condition") or "T0R0").is_clean
    return (not record.method.deterministic and not random
            and record.seed != int(task.spec.get("seed", 0)))


def rerun_command(record: ResultRecord) -> str:
    """The command that recomputes `record` with this code."""
    from safl_bench.sources import root_options

    root = root_options(record.task.source_kind, record.task.spec.get("rotated"))
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
        results[name] = rescore_outcomes(mode.queries)
    return dataclasses.replace(record, results=results, metrics_version=METRICS_VERSION)


def rescore_outcomes(queries: QueryOutcomes) -> ModeResult:
    """A matching mode's measures and curves recomputed under this code's metrics version from
    its per-query outcomes (Recall@N where the outcomes hold ranks: single-frame mode)."""
    o = queries.outcomes()
    return mode_result_from_evaluation(
        evaluate_outcomes(o, recall_at=RECALL_AT if o.true_rank is not None else ()), o)


def task_info(spec: TaskSpec, source_label: str, **extra: Any) -> TaskInfo:
    """TaskInfo of a task spec run on the data source labelled `source_label`.

    `extra` (e.g. data_fingerprint=...) is stored in the spec dict beside the definition.
    """
    return TaskInfo(
        id=spec.id,
        version=int(spec.version),
        protocol=cast(ProtocolName, spec.protocol),
        sequence=spec.sequence,
        condition=spec.condition.name if spec.protocol == "paper" else None,
        source_kind=cast(SourceKind, spec.source),
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
    task's sequence (`safl_bench.methods.training_data.seen_note`).

    `matcher` may be a dict or a dataclass such as `MatcherConfig` (stored as JSON).
    """
    from safl_bench.methods.training_data import seen_note

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
                                   task.sequence, task.spec),
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
    """A record file that could not be used, and why; `corrupt` when it is not a valid record
    (unreadable, not JSON, or against the schema) rather than a duplicate or an outdated one."""

    path: Path
    reason: str
    corrupt: bool = False

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
            problems.append(Problem(path, exc.reason, corrupt=True))
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

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    method: MethodInfo
    task: TaskInfo
    seed: Count
    matcher: dict[str, Any]
    results: ModeResults
    describe_frames_per_s: Amount  # batched throughput measured while evaluating
    matcher_s: Amount
    evaluated_on: Name  # "this process", "2 local worker processes", "Ray cluster (auto)"
    metrics_version: MetricsVersion = METRICS_VERSION
    #: retrieval methods: the median ms of the method's own call per query, measured while
    #: evaluating (their timing: `safl_bench.methods.retrieval`); None for descriptor methods
    query_ms: Amount | None = None


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
    _validate(_EVALUATED, data, path)  # refuse to write what could not be read back
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
    return _validate(_EVALUATED, data, p)


# --------------------------------------------------------------------------------------------
# Validation and the published schema


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not allowed")


def _record_defaults(data: Any) -> Any:
    """What a record file means by an absent key that the parts default otherwise: without
    ``metrics_version`` it predates it (version 1); ``schema`` must be there."""
    if isinstance(data, dict):
        if "schema" not in data:
            raise ValueError("schema: missing")
        return {"metrics_version": 1, **data}
    return data


def _evaluated_defaults(data: Any) -> Any:
    """An evaluated cell's file without ``metrics_version`` predates it (version 1)."""
    return {"metrics_version": 1, **data} if isinstance(data, dict) else data


_RECORD: TypeAdapter[ResultRecord] = TypeAdapter(
    Annotated[ResultRecord, BeforeValidator(_record_defaults)])
_EVALUATED: TypeAdapter[EvaluatedCell] = TypeAdapter(
    Annotated[EvaluatedCell, BeforeValidator(_evaluated_defaults)])

#: How pydantic's error types read in a record's problem line.
_MESSAGES: dict[str, Callable[[Any], str]] = {
    "missing": lambda e: "missing",
    "int_type": lambda e: f"expected an integer, got {type(e['input']).__name__}",
    "float_type": lambda e: f"expected a number, got {type(e['input']).__name__}",
    "string_type": lambda e: f"expected a string, got {type(e['input']).__name__}",
    "list_type": lambda e: f"expected a list, got {type(e['input']).__name__}",
    "dict_type": lambda e: f"expected an object, got {type(e['input']).__name__}",
    "dataclass_type": lambda e: f"expected an object, got {type(e['input']).__name__}",
    "finite_number": lambda e: f"must be a finite number, got {e['input']!r}",
    "string_too_short": lambda e: "must not be empty",
    "string_pattern_mismatch": lambda e: f"expected a positive integer N, got {e['input']!r}",
    "literal_error": lambda e: f"must be one of {e['ctx']['expected']}, got {e['input']!r}",
    "greater_than_equal": lambda e: f"must be >= {e['ctx']['ge']}, got {e['input']}",
    "less_than_equal": lambda e: (f"must be a fraction in [0, 1], got {e['input']}"
                                  if e["ctx"]["le"] == 1 and isinstance(e["input"], float)
                                  else f"must be <= {e['ctx']['le']}, got {e['input']}"),
    "value_error": lambda e: str(e["ctx"]["error"]),
}


def _problem(error: Any) -> str:
    """One pydantic error as "field.path[i]: what is wrong"."""
    where = ""
    for part in error["loc"]:
        if part == "[key]":
            continue
        where += f"[{part}]" if isinstance(part, int) else (f".{part}" if where else str(part))
    kind = error["type"]
    message = _MESSAGES[kind](error) if kind in _MESSAGES else error["msg"]
    return f"{where}: {message}" if where else message


def _validate(adapter: TypeAdapter[Any], data: Any, path: Path) -> Any:
    """`data` validated by `adapter`; CorruptRecordError naming `path` and the first bad field."""
    try:
        return adapter.validate_python(data)
    except _ValidationError as exc:
        raise CorruptRecordError(path, _problem(exc.errors()[0])) from None


def record_schema() -> dict[str, Any]:
    """The JSON Schema of a result record file (what `ResultRecord.from_json` accepts)."""
    schema = TypeAdapter(ResultRecord).json_schema(mode="validation")
    schema["required"] = sorted({*schema.get("required", []), "schema"})
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "title": "safl-bench result record",
            "description": f"One run of one method on one task with one seed, schema version "
                           f"{SCHEMA_VERSION} (safl_bench.results.records).",
            **{k: v for k, v in schema.items() if k not in ("title", "description")}}
