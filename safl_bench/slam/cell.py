"""One loop-closure cell: a (method, revisit task, seed) record's matches through the pose graph.

`run_slam` reads the record's per-query outcomes of one matching mode (each query's matched
database frame, confidence and label: `safl_bench.results.records.QueryOutcomes`), the task's
ground-truth poses (positions and headings of its frames), and returns what the closures the
record accepts at a confidence threshold do to the trajectory, with every back-end
(`backend.BACKENDS`), beside the odometry alone. Nothing is recomputed from views.

Poses: the revisit protocol's queries are its database frames (every `step`-th frame of the
sequence), so pose i is query i and database frame i; the first ``max_frames`` of them when the
record's evaluation settings limit the frames. A record holds the outcomes of its scored queries,
``[max(context_queries, trim_queries), M - trim_queries)`` of the M matched
(`safl_bench.evaluation.cell.scored_queries`), so stored outcome k is pose ``start + k``.

Closures: every scored query whose match has a confidence at or above the threshold. It is true
when the record labels it correct (its match lies within the task's true-positive radius); an
ambiguous match (in the band between the radii) or a wrong one is a false closure. Threshold:
a number in the range of the record's confidences, or None for the oracle operating point (the
lowest threshold at which every accepted closure is true, chosen on the cell itself: peeking,
and named so wherever it is printed).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from safl_bench.common.atomic import atomic_write_text
from safl_bench.errors import ConfigError, DataError
from safl_bench.evaluation import uncertainty
from safl_bench.evaluation.metrics import AMBIGUOUS, CORRECT, Outcomes
from safl_bench.evaluation.uncertainty import Interval
from safl_bench.results.records import ResultRecord, record_path, rerun_command, utc_now
from safl_bench.slam.backend import BACKENDS, solve, trajectory_errors
from safl_bench.slam.model import (
    DEFAULT_DRIFT,
    Closures,
    closure_measurements,
    drift_level,
    simulate_odometry,
)

if TYPE_CHECKING:
    from safl_bench.tasks.task import Task

#: Version of this stage's model and output; bumped when either changes.
SLAM_VERSION = 2
#: What a result file holds (`kind` in its JSON), so that it is told apart from a record.
RESULT_KIND = "safl-bench slam cell"
DEFAULT_RPE_DELTA_M = 100.0
#: SLAM seeds per cell by default: seeds 0 to 4 of the drift and closure-noise draws, all from the
#: one record (revisit tasks have no noise, so they are recorded for one seed).
DEFAULT_SLAM_SEEDS = 5

#: The deployed operating point: each revisit task's threshold is the one that keeps 100 %
#: precision in the same method's record on the task named here, a *different* sequence, so no
#: threshold is chosen on the sequence it is scored on. KITTI 00 and 02 exchange theirs (the
#: issue's own example); 05 and 06 exchange theirs likewise (each the other's nearest in length
#: and setting among the four with revisits, symmetric like 00/02, and fixed before any SLAM
#: number was seen); the synthetic default's 00 and 09 exchange theirs. Rotated-query tasks take
#: their plain sibling's partner.
DEPLOY_FROM: dict[str, str] = {
    "SAFL/BEVKITTI00-Revisit-v0": "SAFL/BEVKITTI02-Revisit-v0",
    "SAFL/BEVKITTI02-Revisit-v0": "SAFL/BEVKITTI00-Revisit-v0",
    "SAFL/BEVKITTI05-Revisit-v0": "SAFL/BEVKITTI06-Revisit-v0",
    "SAFL/BEVKITTI06-Revisit-v0": "SAFL/BEVKITTI05-Revisit-v0",
    "SAFL/Synth00-Revisit-v4": "SAFL/Synth09-Revisit-v4",
    "SAFL/Synth09-Revisit-v4": "SAFL/Synth00-Revisit-v4",
    "SAFL/Synth00-Revisit-v6": "SAFL/Synth09-Revisit-v6",
    "SAFL/Synth09-Revisit-v6": "SAFL/Synth00-Revisit-v6",
}


def deploy_source(task_id: str) -> str:
    """The task whose threshold is deployed on `task_id` (`DEPLOY_FROM`); a ConfigError naming
    the flag that gives one for a task without a pairing."""
    other = DEPLOY_FROM.get(task_id) or DEPLOY_FROM.get(task_id.replace("-RotQueries", ""))
    if other is None:
        raise ConfigError(f"task {task_id} has no deployment pairing (safl_bench.slam.cell."
                          "DEPLOY_FROM); name the task to choose its threshold on with "
                          "--threshold-from ID")
    return other


@dataclass(frozen=True)
class SlamSettings:
    """What a loop-closure cell is run with: the matching mode whose matches become closures,
    the odometry drift level, the confidence threshold (None: the oracle operating point) and
    the distance of the RPE."""

    mode: str = "sequence"
    drift: str = DEFAULT_DRIFT
    threshold: float | None = None
    rpe_delta_m: float = DEFAULT_RPE_DELTA_M
    #: set when `threshold` was chosen elsewhere (`deployed_threshold`: on another sequence),
    #: saying where; it is then applied as it is, outside this cell's confidences too (accepting
    #: none or every match), and None accepts none
    threshold_rule: str | None = None
    #: the SLAM seed: the draw of the odometry drift and of the closures' noise (None: the
    #: record's seed). Seed s is the same drift for every method, so methods pair by seed.
    seed: int | None = None


@dataclass(frozen=True)
class BackendResult:
    """One back-end's outcome: errors (None when it did not converge), how it ended, and for GNC
    the true and false closures it kept."""

    backend: str
    converged: bool
    note: str
    ate_m: float | None
    rpe_m: float | None
    kept_true: int | None = None
    kept_false: int | None = None


@dataclass(frozen=True)
class SlamResult:
    """A loop-closure cell's result (written as JSON by `write_result`)."""

    method: str  # name@version
    task: str
    seed: int
    settings: dict[str, Any]
    threshold: float | None  # the one applied (None: no closure accepted)
    threshold_rule: str
    drift: dict[str, Any]
    n_poses: int
    closures_true: int
    closures_false: int
    odometry_ate_m: float
    odometry_rpe_m: float | None
    backends: list[BackendResult]
    seconds: float
    record_created: str
    #: how ATE is measured: after Umeyama's alignment, or (a straight true path) without
    ate_alignment: str = "Umeyama, SE(3), no scale"
    created: str = field(default_factory=utc_now)
    slam_version: int = SLAM_VERSION
    #: the SLAM seed (drift and closure-noise draw; `seed` is the record's)
    slam_seed: int | None = None
    #: closures whose measurement is the method's own relative-pose estimate, not simulated
    closures_estimated: int = 0
    kind: str = RESULT_KIND

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> SlamResult:
        """The result `to_json` wrote (a DataError for another kind or version)."""
        if data.get("kind") != RESULT_KIND or data.get("slam_version") != SLAM_VERSION:
            raise DataError(f"not a loop-closure result of version {SLAM_VERSION} (kind "
                            f"{data.get('kind')!r}, version {data.get('slam_version')!r})")
        fields = {f.name for f in dataclasses.fields(cls)}
        values = {k: v for k, v in data.items() if k in fields}
        values["backends"] = [BackendResult(**b) for b in data["backends"]]
        return cls(**values)

    def ate(self, backend: str | None) -> float:
        """ATE of a back-end (None: odometry alone); NaN when it did not converge."""
        if backend is None:
            return self.odometry_ate_m
        for b in self.backends:
            if b.backend == backend:
                return math.nan if b.ate_m is None else b.ate_m
        raise ConfigError(f"no back-end {backend!r}; back-ends: {', '.join(BACKENDS)}")


def _cell(record: ResultRecord) -> str:
    return f"{record.method.name}@{record.method.version} on {record.task.id} seed {record.seed}"


def poses_of(task: Task) -> np.ndarray:
    """(n, 3) ground-truth x, y, yaw of the task's query frames; a DataError for a task whose data
    has no poses, a ConfigError for one whose queries are not its database frames."""
    if task.spec.protocol != "revisit" or not np.array_equal(task.query_frames, task.database_frames):
        raise ConfigError(f"task {task.id}: the loop-closure stage runs on revisit tasks (queries "
                          f"are the database frames of one sequence), not on a {task.spec.protocol} "
                          "task")
    if task.query_headings is None:
        raise DataError(f"task {task.id}: its data has no ground-truth poses (headings), which the "
                        "pose graph needs; run it on a source with poses (KITTI, top-view folders, "
                        "the synthetic default)")
    return np.column_stack([task.query_positions, task.query_headings])


def oracle_threshold(confidence: np.ndarray, correct: np.ndarray) -> float | None:
    """The lowest confidence at which every accepted match is correct (None: the most confident
    match is not, so no threshold keeps any closure true)."""
    wrong = confidence[~correct]
    ceiling = float(wrong.max()) if len(wrong) else -math.inf
    above = confidence[correct & (confidence > ceiling)]
    return float(above.min()) if len(above) else None


def deployed_threshold(record: ResultRecord, mode: str = "sequence") -> float | None:
    """The threshold at which `record` reaches its recall at 100 % precision (the lowest that
    accepts no wrong match there, matches in the ambiguous band between the radii counting for
    neither side, as the metrics count them), to be deployed on another cell; None when none
    does. Reads only confidences and labels, so any record with per-query outcomes will do."""
    result = record.results.get(mode)
    if result is None or result.queries is None:
        raise DataError(f"{_cell(record)}: the record holds no per-query outcomes of its {mode!r} "
                        f"matches to choose a threshold on; recompute it: {rerun_command(record)}")
    o = result.queries.outcomes()
    # precision as the revisit metrics count it: a match in the band between the radii is
    # neither a true nor a false positive (`evaluation.metrics`), so it neither sets nor blocks
    # the threshold; the threshold is the one behind the record's recall at 100 % precision
    scored = np.isfinite(o.confidence) & (o.label != AMBIGUOUS)
    return oracle_threshold(o.confidence[scored], o.label[scored] == CORRECT)


def run_slam(record: ResultRecord, task: Task, settings: SlamSettings | None = None) -> SlamResult:
    """The loop-closure cell of `record` on `task` (module doc). Raises DataError for a record
    without the per-query matches it needs (naming the command that recomputes it), ConfigError
    for a threshold outside the record's confidences."""
    settings = settings or SlamSettings()
    level = drift_level(settings.drift)
    if not settings.rpe_delta_m > 0:
        raise ConfigError(f"the RPE distance must be > 0 m, got {settings.rpe_delta_m}")
    t0 = time.perf_counter()
    if record.task.id != task.id:
        raise ConfigError(f"the record of {_cell(record)} is not of task {task.id}")
    poses, start, outcomes = stored_matches(record, task, settings.mode)
    n = len(poses)
    slam_seed = _slam_seed(record, settings)
    assert outcomes.match is not None  # stored_matches checked it
    answered = outcomes.match >= 0
    confidence = outcomes.confidence
    correct = outcomes.label == CORRECT
    if settings.threshold_rule is not None:
        threshold, rule = settings.threshold, settings.threshold_rule
    elif settings.threshold is None:
        threshold = oracle_threshold(confidence[answered], correct[answered])
        rule = ("oracle: the lowest at which every accepted closure is true, chosen on this cell"
                + ("" if threshold is not None else "; none is"))
    else:
        threshold = float(settings.threshold)
        values = confidence[answered]
        if not len(values):
            raise DataError(f"{_cell(record)}: no query reported a match, so there is no "
                            "threshold to apply")
        low, high = float(values.min()), float(values.max())
        if not low <= threshold <= high:
            raise ConfigError(f"threshold {threshold:g} is outside the confidences of {_cell(record)} "
                              f"({low:g} to {high:g}); pick one in that range")
        rule = "given"
    closures = accepted_closures(poses, start, outcomes, threshold, slam_seed)
    odometry = simulate_odometry(poses, level, slam_seed)
    reference = trajectory_errors(poses, odometry.trajectory, settings.rpe_delta_m)
    results = []
    for name in BACKENDS:
        solution = solve(poses[0], odometry, closures, name)
        if solution.trajectory is None:
            results.append(BackendResult(name, False, solution.note, None, None))
            continue
        errors = trajectory_errors(poses, solution.trajectory, settings.rpe_delta_m)
        kept_true = kept_false = None
        if solution.kept is not None:
            kept_true = int((solution.kept & closures.true).sum())
            kept_false = int((solution.kept & ~closures.true).sum())
        results.append(BackendResult(name, True, solution.note, errors.ate_m, errors.rpe_m,
                                     kept_true, kept_false))
    return SlamResult(
        method=f"{record.method.name}@{record.method.version}", task=task.id, seed=record.seed,
        settings=asdict(settings), threshold=threshold, threshold_rule=rule,
        drift={"level": level.name, "translation_pct": level.translation_pct,
               "heading_deg_per_100m": level.heading_deg_per_100m, "source": level.source},
        n_poses=n, closures_true=int(closures.true.sum()),
        closures_false=int((~closures.true).sum()), odometry_ate_m=reference.ate_m,
        odometry_rpe_m=reference.rpe_m, backends=results,
        seconds=round(time.perf_counter() - t0, 3), record_created=record.created,
        slam_seed=slam_seed,
        closures_estimated=0 if closures.estimated is None else int(closures.estimated.sum()),
        ate_alignment=("Umeyama, SE(3), no scale" if reference.aligned else "none: the true path "
                       "is a straight line; errors in the frame of the first pose"))


def stored_matches(record: ResultRecord, task: Task, mode: str) -> tuple[np.ndarray, int, Outcomes]:
    """What a loop-closure cell reads of `record` (module doc): the task's ground-truth poses
    (the first ``max_frames`` when the record's evaluation limits them), the pose of the first
    stored outcome (``start``) and the stored outcomes of `mode`, with their matches. DataError,
    naming the command that recomputes the record, when it lacks them or they do not fit."""
    result = record.results.get(mode)
    if result is None:
        raise DataError(f"{_cell(record)}: the record has no {mode!r} matching mode "
                        f"(it has {', '.join(record.results)})")
    if result.queries is None:
        raise DataError(f"{_cell(record)}: the record holds no per-query outcomes (metrics version "
                        f"{record.metrics_version}); recompute it: {rerun_command(record)}")
    if result.queries.match is None:
        raise DataError(f"{_cell(record)}: the record predates per-query matches (which database "
                        f"frame each query matched); recompute it: {rerun_command(record)}")
    poses = poses_of(task)
    evaluation = record.matcher.get("evaluation", {})
    trim = int(evaluation.get("trim_queries") or 0)
    max_frames = evaluation.get("max_frames")
    n = len(poses) if max_frames is None else min(len(poses), int(max_frames))
    start = max(task.spec.context_queries, trim)
    outcomes = result.queries.outcomes()
    assert outcomes.match is not None
    if len(outcomes.match) != n - start - trim:
        raise DataError(f"{_cell(record)}: {len(outcomes.match)} stored outcomes, expected "
                        f"{n - start - trim} ({n} frames, queries {start} to {n - trim - 1} scored); "
                        f"recompute it: {rerun_command(record)}")
    if (outcomes.match >= n).any():
        raise DataError(f"{_cell(record)}: a stored match is beyond the task's {n} frames")
    return poses[:n], start, outcomes


def _slam_seed(record: ResultRecord, settings: SlamSettings) -> int:
    """The seed of the drift and closure-noise draws: the settings' own, else the record's."""
    return record.seed if settings.seed is None else int(settings.seed)


def accepted_mask(outcomes: Outcomes, threshold: float | None) -> np.ndarray:
    """Which stored outcomes a threshold accepts as closures: those that matched a frame with
    a confidence at or above `threshold` (None: none)."""
    assert outcomes.match is not None
    answered = outcomes.match >= 0
    if threshold is None:
        return np.zeros_like(answered)
    return answered & (outcomes.confidence >= threshold)


def band_closures(record: ResultRecord, mode: str, threshold: float | None) -> int | None:
    """How many of the closures `threshold` accepts in `record` (matching `mode`) lie in the
    protocol's ambiguous band (3-20 m on the revisit tasks: neither a true place nor beyond the
    false-positive radius); they count as false closures here. None without per-query matches."""
    result = record.results.get(mode)
    if result is None or result.queries is None or result.queries.match is None:
        return None
    outcomes = result.queries.outcomes()
    return int((accepted_mask(outcomes, threshold) & (outcomes.label == AMBIGUOUS)).sum())


def accepted_closures(poses: np.ndarray, start: int, outcomes: Outcomes, threshold: float | None,
                      slam_seed: int) -> Closures:
    """The closures a threshold accepts (module doc): every stored outcome k that matched a
    frame with a confidence at or above `threshold` (None: none), as a closure from pose
    ``start + k`` to its matched frame, true where the record labels it correct, measured as
    `closure_measurements` draws it (the method's own relative pose where it gives one)."""
    assert outcomes.match is not None
    index = np.flatnonzero(accepted_mask(outcomes, threshold))
    own = getattr(outcomes, "relative_pose", None)
    return closure_measurements(poses, start + index, outcomes.match[index],
                                (outcomes.label == CORRECT)[index], outcomes.confidence[index],
                                slam_seed, None if own is None else np.asarray(own)[index])


@dataclass(frozen=True)
class CellTrajectories:
    """What a cell's picture shows: the true poses, the odometry's trajectory, each back-end's
    optimised one (None: did not converge) and the accepted closures."""

    result: SlamResult
    truth: np.ndarray
    odometry: np.ndarray
    optimised: dict[str, np.ndarray | None]
    closures: Closures


def cell_trajectories(record: ResultRecord, task: Task, settings: SlamSettings) -> CellTrajectories:
    """`run_slam` of the cell, with the trajectories it measured (solved once more: a result
    file keeps numbers, not trajectories)."""
    result = run_slam(record, task, settings)
    poses, start, outcomes = stored_matches(record, task, settings.mode)
    slam_seed = _slam_seed(record, settings)
    closures = accepted_closures(poses, start, outcomes, result.threshold, slam_seed)
    odometry = simulate_odometry(poses, drift_level(settings.drift), slam_seed)
    optimised = {name: solve(poses[0], odometry, closures, name).trajectory for name in BACKENDS}
    return CellTrajectories(result, poses, odometry.trajectory, optimised, closures)


def curve_thresholds(record: ResultRecord, mode: str = "sequence", points: int = 10) -> list[float | None]:
    """`points` thresholds from no closure (None) to every match (the lowest confidence), the
    rest at evenly spaced quantiles of the record's answered confidences, highest first."""
    if points < 2:
        raise ConfigError(f"a threshold curve needs at least 2 points, got {points}")
    result = record.results.get(mode)
    if result is None or result.queries is None:
        raise DataError(f"{_cell(record)}: the record holds no per-query outcomes of its {mode!r} "
                        f"matches; recompute it: {rerun_command(record)}")
    confidence = result.queries.outcomes().confidence
    answered = np.sort(confidence[np.isfinite(confidence)])[::-1]
    if not len(answered):
        raise DataError(f"{_cell(record)}: no query reported a match, so there is no curve")
    levels = np.quantile(answered, np.linspace(1.0, 0.0, points)[1:], method="lower")
    return [None, *dict.fromkeys(float(v) for v in levels)]


def threshold_curve(record: ResultRecord, task: Task, settings: SlamSettings | None = None,
                    points: int = 10) -> list[SlamResult]:
    """The cell at each of `curve_thresholds` (the settings' own threshold is ignored): what the
    trajectory error does from no closure to every match."""
    settings = settings or SlamSettings()
    return [run_slam(record, task, dataclasses.replace(
                settings, threshold=t, threshold_rule=f"curve point {k + 1} of {points}"))
            for k, t in enumerate(curve_thresholds(record, settings.mode, points))]


def curve_table(curve: list[SlamResult]) -> str:
    """One line per threshold: closures true and false, ATE of each back-end."""
    first = curve[0]
    names = [b.backend for b in first.backends]
    lines = [f"{first.method} on {first.task} seed {first.seed}: ATE RMSE (m) against the "
             f"threshold; odometry alone {first.odometry_ate_m:.2f} m",
             f"{'threshold':>12}{'true':>6}{'false':>7}" + "".join(f"{n:>15}" for n in names)]
    for r in curve:
        threshold = "none" if r.threshold is None else f"{r.threshold:.4g}"
        cells = "".join(f"{_metres(b.ate_m) if b.converged else 'no conv.':>15}" for b in r.backends)
        lines.append(f"{threshold:>12}{r.closures_true:>6}{r.closures_false:>7}{cells}")
    return "\n".join(lines)


def settings_key(settings: SlamSettings) -> str:
    """A short digest of every setting but the SLAM seed: result files of other settings get
    other names, and a re-run with the same ones finds its own."""
    import hashlib

    data = asdict(settings)
    data.pop("seed")
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:10]


def result_path(results_dir: str | os.PathLike[str], record: ResultRecord,
                settings: SlamSettings | None = None) -> Path:
    """Where a record's loop-closure result goes: beside the record,
    ``slam-seed-<n>.s<slam seed>.<settings digest>.json`` (a name `load_records`, which reads
    ``seed-*.json``, never takes for a record): one file per (cell, SLAM seed, settings)."""
    settings = settings or SlamSettings()
    path = record_path(results_dir, record.method.name, record.method.version, record.task.id,
                       record.seed)
    slam_seed = record.seed if settings.seed is None else int(settings.seed)
    return path.with_name(f"slam-{path.stem}.s{slam_seed}.{settings_key(settings)}.json")


def write_result(path: str | os.PathLike[str], result: SlamResult) -> Path:
    """Write `result` as indented JSON, atomically."""
    text = json.dumps(result.to_json(), indent=2, sort_keys=True, allow_nan=False) + "\n"
    atomic_write_text(Path(path), text)
    return Path(path)


def read_result(path: str | os.PathLike[str]) -> SlamResult | None:
    """The result written at `path`, or None when there is none of this version (a re-run then
    computes it again)."""
    try:
        return SlamResult.from_json(json.loads(Path(path).read_text()))
    except (OSError, ValueError, TypeError, KeyError, DataError):
        return None


def run_seeds(record: ResultRecord, task: Task, settings: SlamSettings, seeds: Sequence[int],
              results_dir: str | os.PathLike[str] | None = None) -> list[SlamResult]:
    """The cell at each SLAM seed of `seeds` (drift and closure-noise draw s, all from the one
    record). With `results_dir`, each is written atomically to its `result_path`, and one
    already written there with the same settings and record is read instead (a re-run resumes)."""
    out = []
    for s in seeds:
        seeded = dataclasses.replace(settings, seed=int(s))
        path = None if results_dir is None else result_path(results_dir, record, seeded)
        done = None if path is None else read_result(path)
        if (done is not None and done.settings == asdict(seeded)
                and done.record_created == record.created):
            out.append(done)
            continue
        result = run_slam(record, task, seeded)
        if path is not None:
            write_result(path, result)
        out.append(result)
    return out


def seed_interval(values: Sequence[float], n_poses: int = 0) -> Interval:
    """Mean over SLAM seeds and its 95 % interval, by the project's bootstrap over seeds
    (`safl_bench.evaluation.uncertainty`: the same seed draws, replicates and level as every
    other cell's interval; no query resampling, a trajectory error is one number per seed).
    NaN (a back-end that did not converge on some seed) makes the mean n/a."""
    return _seed_sample(values).interval(n_poses)


@dataclass(frozen=True)
class _SeedSample:
    point: float
    values: np.ndarray  # (replicates,) means over the drawn seeds
    n_seeds: int

    def interval(self, n_poses: int = 0) -> Interval:
        return uncertainty._interval(self.point, self.values, self.n_seeds, n_poses)

    def minus(self, other: _SeedSample) -> Interval:
        return uncertainty._interval(self.point - other.point, self.values - other.values,
                                     self.n_seeds, 0)


def _seed_sample(values: Sequence[float]) -> _SeedSample:
    v = np.asarray(values, np.float64)
    if not len(v):
        raise DataError("no SLAM seed to compute an interval from")
    rng = np.random.default_rng(uncertainty.BOOTSTRAP_SEED)
    draws = uncertainty._draws(len(v), rng, uncertainty.REPLICATES)
    return _SeedSample(float(v.mean()), v[draws].mean(axis=1), len(v))


def paired_ate_difference(a: Sequence[float], b: Sequence[float]) -> Interval:
    """Mean ATE of A minus B over the same SLAM seeds (`a[s]`, `b[s]`: seed s of each, the same
    drift) and its 95 % interval: the same seed draws for both sides, so the drift they share
    cancels."""
    if len(a) != len(b) or not len(a):
        raise DataError(f"a paired comparison needs the same SLAM seeds on both sides, got "
                        f"{len(a)} and {len(b)}")
    return _seed_sample(a).minus(_seed_sample(b))


def summary_table(results: Sequence[SlamResult]) -> str:
    """One cell over its SLAM seeds: mean ATE and 95 % interval of odometry alone and of each
    back-end, the closures accepted (mean true/false per seed), non-converged seeds named."""
    first = results[0]
    seeds = [r.slam_seed for r in results]
    threshold = "none (no closure)" if first.threshold is None else f"{first.threshold:g}"
    lines = [f"{first.method} on {first.task}: {first.n_poses} poses, SLAM seeds "
             f"{', '.join(str(s) for s in seeds)} (drift {first.drift['level']})",
             f"threshold {threshold} ({first.threshold_rule})",
             f"closures accepted: {first.closures_true} true, {first.closures_false} false"
             + (f" ({first.closures_estimated} measured by the method's own relative pose)"
                if first.closures_estimated else ""),
             "", f"{'back-end':<16}{'ATE RMSE (m), mean [95 % interval]':>38}  note"]
    for name in (None, *BACKENDS):
        values = [r.ate(name) for r in results]
        failed = [r.slam_seed for r, v in zip(results, values, strict=True) if v != v]
        note = f"did not converge on seed(s) {', '.join(map(str, failed))}" if failed else ""
        text = seed_interval(values, first.n_poses).format(decimals=2)
        lines.append(f"{name or 'odometry alone':<16}{text:>38}  {note}")
    return "\n".join(lines)


def _metres(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def table(result: SlamResult) -> str:
    """The result as a few lines of text: settings, closures, and one row per back-end."""
    drift = result.drift
    threshold = "none (no closure)" if result.threshold is None else f"{result.threshold:g}"
    delta = result.settings["rpe_delta_m"]
    lines = [
        f"{result.method} on {result.task} seed {result.seed}: {result.n_poses} poses, "
        f"{result.settings['mode']} matches",
        f"odometry drift {drift['level']} ({drift['translation_pct']:g} %, "
        f"{drift['heading_deg_per_100m']:g} deg/100 m); threshold {threshold} ({result.threshold_rule})",
        f"closures accepted: {result.closures_true} true, {result.closures_false} false; ATE "
        f"alignment: {result.ate_alignment}",
        "",
        f"{'back-end':<16}{'ATE RMSE (m)':>14}{f'RPE {delta:g} m (m)':>16}  note",
        f"{'odometry alone':<16}{_metres(result.odometry_ate_m):>14}{_metres(result.odometry_rpe_m):>16}",
    ]
    for b in result.backends:
        if not b.converged:
            lines.append(f"{b.backend:<16}{'did not converge':>30}  {b.note}")
            continue
        note = b.note
        if b.kept_true is not None:
            note = f"kept {b.kept_true} true, {b.kept_false} false closures"
        lines.append(f"{b.backend:<16}{_metres(b.ate_m):>14}{_metres(b.rpe_m):>16}  {note}")
    lines.append(f"({result.seconds:.2f} s)")
    return "\n".join(lines)
