"""The training curve of a run's snapshots: AUC against training steps (the paper's Figure 14).

`safl-bench train --snapshot-every K` saves the encoder every K steps under
`<run>/snapshots/<method>-step<N>.safetensors`. `measure_curve` runs each snapshot on a set of
tasks through the ordinary runner (`safl_bench.run.runner.run_grid`: one record per snapshot,
task and seed under `<out>/records/step<N>/`, reused when the command runs again, so an
interrupted curve resumes) and writes `<out>/train_log.jsonl`, one line per snapshot in the
format the leaderboard's training figure reads (`safl_bench.leaderboard.training_logs`), with
the step count as "iteration".

Choices:

* Conditions: T1R2, T5R2, T10R2 and T20R2 on sequence 00 by default, the four panels of the
  authors' training figure (CNN-GAN/Top-Mapping 25be0fd, `src/plot/plotPaper2.py:107`, which
  reads checkpoints 1-28 of both runs at :113-114). 00 is the paper protocol's TEST sequence:
  the curve is a figure of how training went, and every line and file says it was measured on
  the test sequence.
* Measure: the sequence matcher's ROC AUC (the figure's y axis), our AUC without the hand edits
  of the authors' figure (plotPaper2.py:122-123 subtracts 0.1 from BiGAN's).
* One noise seed (0 by default): a curve point is a look at one draw, not a table cell.
* Matcher preset: `authors` by default, the paper-era evaluation of learned features.
* `select_best=True` also writes `<out>/best-on-test.safetensors`: the snapshot whose mean AUC
  over the curve's tasks is highest, as the authors picked their checkpoint (among ~50, on the
  00 test conditions: plotPaper2.py:24-26). Its weights record `selected_on`, which the records
  made with it carry, so every table that shows them can say the checkpoint was selected on
  the test set. Ties go to the earliest snapshot.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from safl_bench.common.atomic import atomic_write_text
from safl_bench.errors import ConfigError, DataError

SNAPSHOT_RE = re.compile(r"^(?P<method>.+)-step(?P<step>\d+)\.safetensors$")
#: The authors' training figure's conditions (plotPaper2.py:107 at 25be0fd).
CURVE_CONDITIONS = ("T1R2", "T5R2", "T10R2", "T20R2")
BEST = "best-on-test.safetensors"
LOG = "train_log.jsonl"


@dataclass(frozen=True)
class Snapshot:
    """One saved encoder of a training run."""

    step: int
    path: Path


@dataclass
class CurvePoint:
    """The AUC of one snapshot per task condition."""

    step: int
    auc: dict[str, float] = field(default_factory=dict)

    @property
    def mean(self) -> float:
        return sum(self.auc.values()) / len(self.auc) if self.auc else float("nan")


def snapshots(run_dir: Path) -> list[Snapshot]:
    """The run's snapshots, by step; DataError when there are none."""
    folder = run_dir / "snapshots"
    found = []
    for path in sorted(folder.glob("*.safetensors")) if folder.is_dir() else []:
        m = SNAPSHOT_RE.match(path.name)
        if m:
            found.append(Snapshot(int(m["step"]), path))
    if not found:
        raise DataError(f"{folder} holds no snapshots (<method>-step<N>.safetensors); train with "
                        "`safl-bench train --snapshot-every K`")
    return sorted(found, key=lambda s: s.step)


def run_info(run_dir: Path) -> dict[str, Any]:
    """The run's train.json (written when training finishes), or {} while it is still running."""
    path = run_dir / "train.json"
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}: not JSON ({exc})") from None
    return data if isinstance(data, dict) else {}


def measure_curve(
    run_dir: Path,
    task_ids: Sequence[str],
    out: Path,
    *,
    evaluation: Any,
    bev_root: str | None = None,
    kitti_root: str | None = None,
    seed: int = 0,
    select_best: bool = False,
    source_label: str | None = None,
    measured_on: str = "KITTI 00 (test sequence)",
    log: Callable[[str], None] = print,
) -> list[CurvePoint]:
    """Evaluate every snapshot of `run_dir` on `task_ids` (module docstring); returns the curve."""
    from safl_bench.methods.method import Method
    from safl_bench.run.runner import RunOptions, run_grid

    shots = snapshots(run_dir)
    if not task_ids:
        raise ConfigError("no tasks to draw the curve on")
    points: list[CurvePoint] = []
    trained_source: str | None = None
    for shot in shots:
        method = Method.load(shot.path)
        trained_source = trained_source or ((method.weights_info or {}).get("trained_on") or {}).get("source")
        options = RunOptions(results_dir=out / "records" / f"step{shot.step:06d}", seed=seed,
                             bev_root=bev_root, kitti_root=kitti_root, evaluation=evaluation,
                             timing_frames=5, timing_repeats=1, progress=False)
        outcomes = run_grid([method], list(task_ids), options, log=lambda _m: None)
        point = CurvePoint(shot.step)
        for outcome in outcomes:
            if outcome.record is None:
                raise DataError(f"snapshot {shot.path.name} on {outcome.task_id}: {outcome.message}")
            condition = outcome.record.task.condition or outcome.task_id
            auc = outcome.record.results["sequence"].metrics.auc
            point.auc[condition] = float("nan") if auc is None else auc
        points.append(point)
        log(f"step {shot.step}: " + ", ".join(f"{c} {v:.3f}" for c, v in point.auc.items()))
    label = source_label or trained_source or run_info(run_dir).get("data", {}).get("source")
    lines = [json.dumps({"iteration": p.step, "val_auc": p.auc, "val_tasks": list(task_ids),
                         "source": label, "measured_on": measured_on, "seed": seed},
                        sort_keys=True) for p in points]
    atomic_write_text(out / LOG, "".join(line + "\n" for line in lines))
    if select_best:
        best = max(points, key=lambda p: (p.mean, -p.step))
        chosen = next(s for s in shots if s.step == best.step)
        weights = Method.load(chosen.path)
        trained = dict((weights.weights_info or {}).get("trained_on") or {})
        trained["selected_on"] = (f"{measured_on}: the highest mean AUC over "
                                  f"{', '.join(best.auc)} among {len(points)} snapshots "
                                  f"(step {best.step}), as the authors chose their checkpoint")
        weights.save(out / BEST, parts=("encoder",), trained_on=trained)
        log(f"best on the test sequence: step {best.step} (mean AUC {best.mean:.3f}) -> {out / BEST}")
    return points
