"""Which records go into which table, and how seeds are combined into one cell.

Rules (the leaderboard's README states them for readers):

* A table holds records of one data source (kind and label: the synthetic default with its seed,
  or KITTI), one protocol, one test sequence (paper protocol) and ONE task version. Records of
  another task version form their own table, so versions are never mixed.
* Within a table, records of one task id must share the task's spec fingerprint. If they do not
  (the task changed without a version bump), only the records with the newest spec are used and
  a note says which were left out.
* Seeds: a table's seed set is every seed any of its records used. A cell shows the mean over
  its own seeds and its 95 % interval over seeds and queries (`leaderboard.intervals`); a cell
  whose seeds are not the table's names its seeds in the cell and in a note, and is compared
  with the others on the seeds both have (paired), never as if its runs were alike.
"""

from __future__ import annotations

import re
from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from safl_bench.errors import ConfigError
from safl_bench.results.records import ResultRecord
from safl_bench.views.noise import PAPER_CONDITIONS, Condition


@dataclass(frozen=True, order=True)
class TableKey:
    """What a table's records share."""

    source_kind: str
    source_label: str
    protocol: str
    sequence: str  # "" for the revisit protocol, whose table spans sequences
    task_version: int

    @property
    def source_slug(self) -> str:
        """The data source as a file-name part, e.g. 'synthetic-default-seed-0', 'kitti'."""
        return slugify(self.source_label)

    @property
    def stem(self) -> str:
        """File-name stem of this table's outputs, e.g. 'paper-00-v0', 'revisit-v0'."""
        if self.protocol == "paper":
            return f"paper-{slugify(self.sequence)}-v{self.task_version}"
        return f"{self.protocol}-v{self.task_version}"

    @property
    def caption(self) -> str:
        """Heading text naming the source, sequence and task version."""
        where = f"sequence {self.sequence}, " if self.sequence else ""
        return f"{self.source_label}, {where}{self.protocol} protocol, task version v{self.task_version}"


def slugify(text: str) -> str:
    """Lower-case, alphanumerics and '-' only (for file names)."""
    slug = re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")
    return slug or "unnamed"


def table_key(record: ResultRecord) -> TableKey:
    """The table a record belongs to."""
    task = record.task
    return TableKey(
        source_kind=task.source_kind,
        source_label=task.source_label,
        protocol=task.protocol,
        sequence=task.sequence if task.protocol == "paper" else "",
        task_version=task.version,
    )


def group_records(
    records: Iterable[ResultRecord],
) -> tuple[dict[TableKey, list[ResultRecord]], dict[TableKey, list[str]]]:
    """Records grouped by table (keys sorted), and per table the notes on records left out."""
    groups: dict[TableKey, list[ResultRecord]] = defaultdict(list)
    for record in records:
        groups[table_key(record)].append(record)
    out: dict[TableKey, list[ResultRecord]] = {}
    notes: dict[TableKey, list[str]] = {}
    for key in sorted(groups):
        kept, dropped = _newest_spec_only(groups[key])
        out[key] = sorted(kept, key=lambda r: r.key)
        notes[key] = dropped
    return out, notes


def _newest_spec_only(records: list[ResultRecord]) -> tuple[list[ResultRecord], list[str]]:
    by_task: dict[str, list[ResultRecord]] = defaultdict(list)
    for record in records:
        by_task[record.task.id].append(record)
    kept: list[ResultRecord] = []
    notes: list[str] = []
    for task_id in sorted(by_task):
        task_records = by_task[task_id]
        prints = {r.task.spec_fingerprint for r in task_records}
        if len(prints) == 1:
            kept.extend(task_records)
            continue
        newest = max(task_records, key=lambda r: (r.created, r.task.spec_fingerprint))
        newest_print = newest.task.spec_fingerprint
        kept.extend(r for r in task_records if r.task.spec_fingerprint == newest_print)
        left_out = sorted(
            f"{r.method.name} v{r.method.version} seed {r.seed}"
            for r in task_records
            if r.task.spec_fingerprint != newest_print
        )
        notes.append(
            f"{task_id}: records made with an older spec of this task version were left out "
            f"({'; '.join(left_out)}); the task changed without a version bump — rerun them."
        )
    return kept, notes


def condition_order(names: Iterable[str]) -> list[str]:
    """The paper's twelve conditions in Table II order, then any others by (heading, translation)."""
    present = set(names)
    paper = [c.name for c in PAPER_CONDITIONS]
    ordered = [name for name in paper if name in present]
    others = sorted(present - set(paper), key=_condition_sort_key)
    return ordered + others


def _condition_sort_key(name: str) -> tuple[int, float, float, str]:
    try:
        cond = Condition.parse(name)
    except ConfigError:
        return (1, 0.0, 0.0, name)
    return (0, cond.heading_rad, cond.translation_m, name)


@dataclass(frozen=True)
class Cell:
    """One table cell over the seeds it has records of.

    `mean` is None when the metric is undefined for some seed (e.g. a task without positives).
    `low`, `high`: its 95 % interval (None when none can be computed); `seeds`: its seeds;
    `measurements`: how many distinct measurements its seeds' values are (a timing the run took
    once and every seed's record carries is one), None where each seed is its own (scores).
    """

    mean: float | None
    low: float | None = None
    high: float | None = None
    seeds: frozenset[int] = frozenset()
    measurements: int | None = None

    @property
    def n_seeds(self) -> int:
        return len(self.seeds)


def aggregate(values: Mapping[int, float | None]) -> Cell | None:
    """The mean of per-seed values as a Cell (no interval yet), None (missing) when there is none."""
    if not values:
        return None
    seeds = frozenset(values)
    ordered = [values[s] for s in sorted(seeds)]
    if any(v is None for v in ordered):
        return Cell(mean=None, seeds=seeds)
    return Cell(mean=float(np.mean(np.asarray(ordered, dtype=np.float64))), seeds=seeds)


def seed_set(records: Iterable[ResultRecord]) -> frozenset[int]:
    """Every seed used by any of `records`."""
    return frozenset(r.seed for r in records)


def format_seeds(seeds: Iterable[int]) -> str:
    """'0' or '0, 1, 2'."""
    return ", ".join(str(s) for s in sorted(seeds))
