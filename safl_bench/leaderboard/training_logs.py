"""Training logs read for the training-stability figure (the paper's Figure 14).

`safl-bench train` appends one JSON object per epoch to `<dir>/<method>/train_log.jsonl`:

    {"epoch": 3, "losses": {...}, "val_auc": {"T1R1": 0.81, ...}, "source": "synthetic default (seed 0)"}

"source" (the data source's label) is optional; figures say "source not recorded" without it.
A log may count training steps instead of epochs: lines with "iteration" in place of "epoch"
(`safl-bench train-curve`, from a run's snapshots), and "measured_on" naming what the AUC was
measured on when that is not a validation sequence (e.g. the test sequence); one file holds one
kind of line.
A line that is not such an object is reported by file and line and skipped; when an epoch
appears more than once (a resumed run), its last line wins.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from safl_bench.results.records import Problem

LOG_NAME = "train_log.jsonl"


@dataclass(frozen=True)
class TrainingLog:
    """Validation AUC per epoch and condition of one method's training run."""

    method: str
    path: Path
    source: str | None
    epochs: list[int]  # the x values: epochs, or training steps when unit == "iteration"
    val_auc: dict[str, list[float | None]]  # condition -> value per epoch (None: not measured)
    unit: str = "epoch"
    measured_on: str | None = None  # what the AUC was measured on, when not validation data


def load_training_logs(root: str | os.PathLike[str]) -> tuple[list[TrainingLog], list[Problem]]:
    """Every `<root>/<method>/train_log.jsonl` with at least one valid epoch, sorted by method."""
    base = Path(root)
    logs: list[TrainingLog] = []
    problems: list[Problem] = []
    if not base.is_dir():
        return logs, problems
    for path in sorted(base.glob(f"*/{LOG_NAME}")):
        log, bad = read_training_log(path)
        problems.extend(bad)
        if log is not None:
            logs.append(log)
    return logs, problems


def read_training_log(path: Path) -> tuple[TrainingLog | None, list[Problem]]:
    """One log file; None if it holds no valid epoch."""
    problems: list[Problem] = []
    by_epoch: dict[int, dict[str, float]] = {}
    sources: set[str] = set()
    units: set[str] = set()
    measured: set[str] = set()
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        return None, [Problem(path, f"cannot be read ({exc})")]
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            data = json.loads(line)
            epoch, aucs, source = _parse_line(data)
        except (json.JSONDecodeError, ValueError) as exc:
            problems.append(Problem(path, f"line {number}: {exc}"))
            continue
        by_epoch[epoch] = aucs
        units.add("iteration" if "iteration" in data else "epoch")
        if isinstance(data.get("measured_on"), str):
            measured.add(data["measured_on"])
        if source:
            sources.add(source)
    if not by_epoch:
        return None, problems
    if len(sources) > 1:
        problems.append(Problem(path, f"mixes data sources {sorted(sources)}; not plotted"))
        return None, problems
    if len(units) > 1:
        problems.append(Problem(path, "mixes epoch and iteration lines; not plotted"))
        return None, problems
    epochs = sorted(by_epoch)
    conditions = sorted({c for aucs in by_epoch.values() for c in aucs})
    val_auc = {c: [by_epoch[e].get(c) for e in epochs] for c in conditions}
    source = next(iter(sources)) if sources else None
    return TrainingLog(path.parent.name, path, source, epochs, val_auc, units.pop(),
                       " / ".join(sorted(measured)) or None), problems


def _parse_line(data: Any) -> tuple[int, dict[str, float], str | None]:
    if not isinstance(data, dict):
        raise ValueError("not a JSON object")
    key = "iteration" if "iteration" in data and "epoch" not in data else "epoch"
    epoch = data.get(key)
    if isinstance(epoch, bool) or not isinstance(epoch, int) or epoch < 0:
        raise ValueError(f"'{key}' must be an integer >= 0, got {epoch!r}")
    raw = data.get("val_auc")
    if not isinstance(raw, dict):
        raise ValueError("'val_auc' must be an object of condition -> AUC")
    aucs: dict[str, float] = {}
    for condition, value in raw.items():
        if value is None:
            continue
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise ValueError(f"val_auc[{condition!r}] must be a finite number, got {value!r}")
        aucs[str(condition)] = float(value)
    source = data.get("source")
    if source is not None and not isinstance(source, str):
        raise ValueError(f"'source' must be a string, got {source!r}")
    return epoch, aucs, source
