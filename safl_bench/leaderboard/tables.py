"""Leaderboard tables built from result records, rendered as Markdown and CSV.

Shapes follow the paper: Table II (recall at 100 % precision, rows = methods, columns = the
twelve noise conditions), the AUC table of Figure 13, Table III (feature inference time in ms per
frame), Recall@1 per condition, plus the revisit-protocol table (F1max, recall at 100 % precision,
AUC and Recall@1 per sequence) and BEVPlace's protocol (Recall@1/5/10 per sequence, beside the
Recall@1 that BEVPlace's paper publishes: `PUBLISHED_BEVPLACE`).
Each method has one row per matching mode ("sequence" = SeqSLAM, "single-frame" = nearest
neighbour), so a reader sees what the sequence matcher adds. Output is deterministic: rows are
sorted, floats have a fixed number of decimals, and nothing depends on the clock or the machine.
"""

from __future__ import annotations

import io
import json
import re
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from safl_bench.leaderboard import intervals
from safl_bench.leaderboard.grouping import (
    Cell,
    TableKey,
    aggregate,
    condition_order,
    format_seeds,
    seed_set,
)
from safl_bench.leaderboard.intervals import BEST, TIED
from safl_bench.results.records import MODES, Metrics, ResultRecord, is_repeat, timed_under_load

MISSING = "—"
UNDEFINED = "n/a"
MODE_LABELS = {"sequence": "sequence", "single_frame": "single-frame"}


@dataclass(frozen=True)
class ValueFormat:
    """How a column's values are shown: multiplied by `scale`, `decimals` digits.

    `better` ("higher" or "lower") makes the Markdown bold the best value of each column among
    rows of the same matching mode (ties all bold, nothing when all are equal); None bolds nothing.
    """

    scale: float = 1.0
    decimals: int = 1
    better: str | None = None

    def number(self, value: float) -> str:
        return f"{value * self.scale:.{self.decimals}f}"


RowKey = tuple[str, str, str]  # (method, method version, matching mode or "")


@dataclass
class Table:
    """A rendered-ready table: row labels, columns, one Cell (or None = missing) per position.

    `marks`: (row, column) -> `intervals.BEST` (bold: best beyond the noise) or `intervals.TIED`
    (tied for best); `spread`: what a cell's bracket is ("bootstrap": the 95 % interval over
    seeds and queries; "range": the lowest and highest of the seeds' values; "timings": the
    lowest and highest of the cell's distinct timings, `Cell.measurements` of them, a cell timed
    once showing its one timing as such, `ONE_TIMING`)."""

    title: str
    key: TableKey
    row_header: tuple[str, str, str]
    rows: list[RowKey]
    columns: list[str]
    formats: list[ValueFormat]
    cells: list[list[Cell | None]]
    seeds: frozenset[int]
    notes: list[str] = field(default_factory=list)
    marks: dict[tuple[int, int], str] = field(default_factory=dict)
    spread: str = "bootstrap"

    @property
    def heading(self) -> str:
        """The heading line: what the values are and which data they come from."""
        return f"{self.title} — {self.key.caption}"

    def value_text(self, cell: Cell | None, fmt: ValueFormat) -> str:
        """The cell's mean as shown ('—' missing, 'n/a' undefined)."""
        if cell is None:
            return MISSING
        if cell.mean is None:
            return UNDEFINED
        return fmt.number(cell.mean)

    def interval_text(self, cell: Cell | None, fmt: ValueFormat) -> str:
        """'[low, high]' of the cell, and its seeds when they are not the table's; '' if none."""
        if cell is None or cell.mean is None:
            return ""
        parts = []
        if cell.low is not None and cell.high is not None:
            parts.append(f"[{fmt.number(cell.low)}, {fmt.number(cell.high)}]")
        if cell.measurements is not None and cell.measurements < cell.n_seeds:
            parts.append(ONE_TIMING if cell.measurements == 1 else f"({cell.measurements} timings)")
        if cell.seeds and cell.seeds != self.seeds:
            parts.append(f"(seed {format_seeds(cell.seeds)})")
        return " ".join(parts)

    def cell_text(self, cell: Cell | None, fmt: ValueFormat) -> str:
        """The cell as the Markdown shows it: 'mean [low, high]' (and its seeds if its own)."""
        interval = self.interval_text(cell, fmt)
        return self.value_text(cell, fmt) + (f" {interval}" if interval else "")

    def markdown(self, level: int = 2) -> str:
        """The table as Markdown: heading, seeds line, table, notes."""
        show_header = [h for h in self.row_header if h]
        lines = [f"{'#' * level} {self.heading}", ""]
        lines.append(seeds_sentence(self))
        lines.append("")
        lines.append("| " + " | ".join([*show_header, *map(_md, self.columns)]) + " |")
        lines.append("|" + "---|" * len(show_header) + "---:|" * len(self.columns))
        for i, row in enumerate(self.rows):
            labels = [_md(v) for v, h in zip(row, self.row_header, strict=True) if h]
            values = []
            for j, fmt in enumerate(self.formats):
                text = self.cell_text(self.cells[i][j], fmt)
                mark = self.marks.get((i, j))
                values.append(f"**{text}**" if mark == BEST else f"≈ {text}" if mark == TIED else text)
            lines.append("| " + " | ".join([*labels, *values]) + " |")
        if self.notes:
            lines.append("")
            lines.extend(f"- {note}" for note in self.notes)
        return "\n".join(lines) + "\n"

    def frame(self) -> pd.DataFrame:
        """The table as a DataFrame of strings (CSV form): numbers without units, '' = missing;
        each column's interval bounds beside it, and its cells' seeds where they differ."""
        data: dict[str, list[str]] = {
            "Source": [self.key.source_label] * len(self.rows),
            "Protocol": [self.key.protocol] * len(self.rows),
            "Sequence": [self.key.sequence] * len(self.rows),
            "Task version": [str(self.key.task_version)] * len(self.rows),
        }
        for h, idx in zip(self.row_header, range(3), strict=True):
            if h:
                data[h] = [row[idx] for row in self.rows]
        for j, (column, fmt) in enumerate(zip(self.columns, self.formats, strict=True)):
            cells = [self.cells[i][j] for i in range(len(self.rows))]
            data[column] = [_csv_value(c, fmt, "mean") for c in cells]
            data[f"{column} low"] = [_csv_value(c, fmt, "low") for c in cells]
            data[f"{column} high"] = [_csv_value(c, fmt, "high") for c in cells]
            if any(c is not None and c.seeds != self.seeds for c in cells):
                data[f"{column} seeds"] = ["" if c is None else format_seeds(c.seeds) for c in cells]
            if self.spread == "timings":
                data[f"{column} timings"] = [
                    "" if c is None or c.measurements is None else str(c.measurements) for c in cells]
            if fmt.better is not None:
                data[f"{column} rank"] = [self.marks.get((i, j), "") for i in range(len(self.rows))]
        data["Seeds"] = [format_seeds(self.seeds)] * len(self.rows)
        return pd.DataFrame(data)

    def csv(self) -> str:
        """The table as CSV text ('\\n' line ends)."""
        return frame_csv(self.frame())


def _md(text: str) -> str:
    return text.replace("|", "\\|")


def _csv_value(cell: Cell | None, fmt: ValueFormat, which: str) -> str:
    if cell is None:
        return ""
    if cell.mean is None:
        return UNDEFINED if which == "mean" else ""
    value = {"mean": cell.mean, "low": cell.low, "high": cell.high}[which]
    return "" if value is None else fmt.number(value)


#: How a cell whose seeds carry one timing says so, in place of a bracket of zero width.
ONE_TIMING = "(1 timing)"


def seeds_sentence(table: Table) -> str:
    """What a cell's value and bracket are, and what bold and '≈' mean."""
    seeds = format_seeds(table.seeds)
    if table.spread == "timings" and len(table.seeds) > 1:
        return (f"Seeds {seeds}: each cell the mean of its seeds' distinct timings [lowest, "
                f"highest]; a cell whose seeds' records carry one timing shows it alone, marked "
                f"'{ONE_TIMING}', and one with fewer distinct timings than seeds says how many; a "
                f"cell with other seeds names them. Missing cells show {MISSING}.")
    if table.spread in ("range", "timings"):
        if len(table.seeds) == 1:
            return f"Seed {seeds}. Missing cells (not run) show {MISSING}."
        return (f"Mean over seeds {seeds} [lowest, highest of the seeds' records]; a cell with "
                f"other seeds names them. Missing cells show {MISSING}.")
    what = (f"Seed {seeds}: each value over its queries [95 % interval over the queries]"
            if len(table.seeds) == 1 else
            f"Mean over seeds {seeds} [95 % interval over seeds and queries]; a cell with other "
            "seeds names them")
    # `safl_bench.uncertainty`: the module's old path (it still imports), kept in the published text
    # so that the committed tables regenerate byte for byte
    return (f"{what} (two-level block bootstrap, `safl_bench.uncertainty`). **Bold**: best of its "
            "column and matching mode beyond the noise (the paired difference to every other "
            "excludes 0); ≈: tied for best (not resolved). Missing cells (not run) show "
            f"{MISSING}.")


# --------------------------------------------------------------------------------------------
# Building tables from records


def _version_key(version: str) -> tuple[int, ...] | tuple[str]:
    parts = re.split(r"[.\-]", version)
    return tuple(int(p) for p in parts) if all(p.isdigit() for p in parts) else (version,)


def _row_sort_key(row: RowKey) -> tuple[object, ...]:
    mode_rank = MODES.index(row[2]) if row[2] in MODES else -1
    version = row[1].removesuffix(UNTRAINED_MARK).removesuffix(SEEN_MARK).removesuffix(PARTLY_SEEN_MARK)
    return (row[0], _version_key(version), version, row[1] != version, mode_rank, row[2])


#: Appended to the version of a row whose records' weights were trained on the task's sequence
#: (every frame the task uses), or on some of the frames it uses: `safl_bench.methods.training_data`.
#: (the same strings as there: this module does not import the methods' package at load)
SEEN_MARK = " (seen in training)"
PARTLY_SEEN_MARK = " (partly seen in training)"
#: Appended to the version of a row whose records ran the untrained (random) networks.
UNTRAINED_MARK = " (untrained)"
#: A cell is never marked best or tied when its method answered fewer than this share of the
#: scored queries with a true place (`safl_bench.evaluation.metrics.answered_share`, the
#: "Abstaining" section there): a measure over its answers alone (the AUC) would rank a method
#: that abstains above ones that answer. Half: a method that leaves most of the places it
#: should find unanswered is not the best at finding them, whatever its answers' ranking.
ANSWERED_MIN = 0.5


def shown_version(record: ResultRecord) -> str:
    """The record's method version as the figures and their files name it: with
    `UNTRAINED_MARK` when it ran untrained networks, so they never merge with trained ones."""
    from safl_bench.methods.training_data import record_untrained

    return record.method.version + (UNTRAINED_MARK if record_untrained(record) else "")


def _row_label(row: RowKey) -> str:
    """A row as the notes name it: method, version, matching mode."""
    return " ".join(part for part in (row[0], f"v{row[1]}", MODE_LABELS.get(row[2], row[2])) if part)


def _answered(records: list[ResultRecord], mode: str) -> float | None:
    """The mean over `records` (a cell's seeds) of the share of queries with a true place that
    reported a match in `mode`; None when a record holds no per-query outcomes."""
    from safl_bench.evaluation.metrics import answered_share

    shares = []
    for record in records:
        result = record.results.get(mode)
        if result is None or result.queries is None:
            return None
        share = answered_share(result.queries.outcomes())
        if share is None:
            return None
        shares.append(share)
    return float(np.mean(shares)) if shares else None


class Value(NamedTuple):
    """One record's value for one table position, and where its interval comes from: the
    record's matching `mode` and the `uncertainty` measure name (None: no bootstrap; the
    bracket is the seeds' range)."""

    row: RowKey
    column: str
    value: float | None
    mode: str = ""
    measure: str | None = None


Extractor = Callable[[ResultRecord], Iterable[Value]]


_FEWER_SEEDS = "compared with other rows on the seeds both have; run the missing seeds to fill them."


def _build(
    key: TableKey,
    records: list[ResultRecord],
    *,
    title: str,
    row_header: tuple[str, str, str],
    columns: list[str],
    formats: list[ValueFormat],
    extract: Extractor,
    notes: Iterable[str] = (),
    fewer_seeds: str = _FEWER_SEEDS,
    combine: Callable[[dict[int, float | None]], Cell | None] | None = None,
) -> Table:
    """The table of `records` (`extract` gives each record's values). `fewer_seeds` ends the note
    on a cell over fewer seeds than the table's: what to make of it and how to fill it.
    `combine`: makes a cell of its seeds' values in place of their mean and bracket (the time
    table's, `_timing_cell`)."""
    from safl_bench.methods.training_data import (
        PARTLY_SEEN_PREFIX,
        record_seen,
        record_untrained,
        seen_mark,
    )

    # repeated runs of an unseedable method (`records.is_repeat`) are that cell's runs, not seeds
    # of the table: they neither widen its seeds nor count as a row over other seeds
    seeds = seed_set([r for r in records if not is_repeat(r)]) or seed_set(records)
    repeated: dict[RowKey, set[int]] = defaultdict(set)
    values: dict[tuple[RowKey, str], dict[int, float | None]] = defaultdict(dict)
    sources: dict[tuple[RowKey, str], dict[int, ResultRecord]] = defaultdict(dict)
    probe: dict[tuple[RowKey, str], tuple[str, str | None]] = {}
    seen_rows: set[RowKey] = set()
    partly: dict[tuple[str, str], str] = {}  # (method, sequence) -> what its weights saw of it
    any_untrained = False
    for record in records:
        note = record_seen(record)
        mark = seen_mark(note)
        if mark == PARTLY_SEEN_MARK and note is not None:
            partly[(record.method.name, record.task.sequence)] = note.removeprefix(PARTLY_SEEN_PREFIX)
        untrained = record_untrained(record)
        any_untrained = any_untrained or untrained
        for v in extract(record):
            row = (v.row[0], v.row[1] + mark, v.row[2])
            if untrained:
                row = (row[0], row[1] + UNTRAINED_MARK, row[2])
            if mark:
                seen_rows.add(row)
            if is_repeat(record):
                repeated[row].add(record.seed)
            values[(row, v.column)][record.seed] = v.value
            sources[(row, v.column)][record.seed] = record
            probe[(row, v.column)] = (v.mode, v.measure)
    rows = sorted({row for row, _ in values}, key=_row_sort_key)
    with_intervals = intervals.enabled()
    bootstrapped = any(measure is not None for _, measure in probe.values())
    cells: list[list[Cell | None]] = []
    for row in rows:
        line: list[Cell | None] = []
        for column in columns:
            if combine is not None:
                line.append(combine(values.get((row, column), {})))
                continue
            cell = aggregate(values.get((row, column), {}))
            if cell is not None and cell.mean is not None and with_intervals:
                cell = _with_interval(cell, values[(row, column)],
                                      list(sources[(row, column)].values()), *probe[(row, column)])
            if cell is not None and repeated.get(row):
                # its runs are one cell's: it is over the seeds it was run at, not over the runs
                cell = replace(cell, seeds=cell.seeds - repeated[row])
            line.append(cell)
        cells.append(line)
    marks: dict[tuple[int, int], str] = {}
    abstaining: dict[RowKey, float] = {}  # row -> the lowest answered share of its cells
    if with_intervals and bootstrapped:
        for j, (column, fmt) in enumerate(zip(columns, formats, strict=True)):
            if fmt.better is None:
                continue
            groups: dict[str, list[intervals.Ranked]] = defaultdict(list)
            for i, row in enumerate(rows):
                cell = cells[i][j]
                if cell is None or cell.mean is None or row in seen_rows:
                    continue  # a cell seen in training is never ranked beside clean ones
                mode, measure = probe[(row, column)]
                share = _answered(list(sources[(row, column)].values()), mode)
                if share is not None and share < ANSWERED_MIN:
                    abstaining[row] = min(share, abstaining.get(row, share))
                    continue  # it abstained: its measures over its answers are not ranked
                groups[row[2]].append(intervals.Ranked(
                    i, cell.mean, float(fmt.number(cell.mean)),
                    tuple(sources[(row, column)].values()), mode, measure))
            for group in groups.values():
                marks.update({(i, j): m for i, m in intervals.rank(group, fmt.better).items()})
    own: dict[tuple[RowKey, tuple[int, ...]], list[str]] = defaultdict(list)
    for row in rows:
        for column in columns:
            have = values.get((row, column))
            if have and row in repeated:
                continue  # its note says what its seeds are (below)
            if have and set(have) != seeds:
                own[(row, tuple(sorted(have)))].append(column)
    all_notes = list(notes)
    retrieval = sorted({f"{r.method.name}@{r.method.version}" for r in records
                        if r.method.kind == "retrieval"})
    if retrieval and any(mode == "sequence" for mode, _ in probe.values()):
        all_notes.append(f"{', '.join(retrieval)}: sequence matcher n/a (a retrieval method gives "
                         "ranked candidates, no difference matrix): single-frame rows only.")
    for (row, theirs), cols in sorted(own.items(), key=lambda kv: (_row_sort_key(kv[0][0]), kv[0][1])):
        all_notes.append(
            f"{_row_label(row)}: {', '.join(cols)} over seed(s) {format_seeds(theirs)} only (the table's: "
            f"{format_seeds(seeds)}); {fewer_seeds}"
        )
    if with_intervals and bootstrapped and any(
            c is not None and c.mean is not None and c.low is None for line in cells for c in line):
        all_notes.append("Cells without an interval come from records without per-query outcomes "
                         "(metrics version 1): never marked best; `safl-bench run --force` "
                         "recomputes them.")
    if any(row[1].removesuffix(UNTRAINED_MARK).endswith(SEEN_MARK) for row in seen_rows):
        # `safl_bench.training_data`: the old path of methods.training_data (it still imports),
        # kept in the published text so that the committed tables regenerate byte for byte
        all_notes.append(f"Rows whose version says '{SEEN_MARK.strip()}': the method's weights "
                         "were trained on this task's sequence (`safl_bench.training_data`); "
                         "their scores measure memory, not generalisation, and are never ranked "
                         "beside the other rows.")
    if partly:
        all_notes.append(f"Rows whose version says '{PARTLY_SEEN_MARK.strip()}': the method's "
                         "weights were trained on some of the frames this task uses, never "
                         "ranked beside the other rows (`safl_bench.methods.training_data`): "
                         + "; ".join(f"{name} on {sequence}: {what}"
                                     for (name, sequence), what in sorted(partly.items())) + ".")
    if any_untrained:
        all_notes.append(f"Rows whose version says '{UNTRAINED_MARK.strip()}': scored with the "
                         "method's untrained (random) networks (`--weights untrained`), not "
                         "trained weights.")
    for row in sorted(repeated, key=_row_sort_key):
        runs = {seed for column in columns for seed in values.get((row, column), {})}
        all_notes.append(
            f"{_row_label(row)}: seeds {format_seeds(runs)} are runs of one cell, repeated because nothing in its task is random and the method "
            "cannot be seeded (`deterministic = False`; `safl_bench.run.runner.REPEATS`): its value "
            "is their mean and its interval covers their spread.")
    if abstaining:
        all_notes.append(
            "Never marked best or tied, as they answered fewer than "
            f"{ANSWERED_MIN:.0%} of the queries with a true place (the rest they reported no "
            "match for; the AUC counts only their answers): " + "; ".join(
                f"{_row_label(row)} answered {share:.0%}" for row, share in sorted(
                    abstaining.items(), key=lambda kv: _row_sort_key(kv[0]))) + ".")
    all_notes.extend(_matcher_notes(records))
    return Table(
        title=title,
        key=key,
        row_header=row_header,
        rows=rows,
        columns=columns,
        formats=formats,
        cells=cells,
        seeds=seeds,
        notes=all_notes,
        marks=marks,
        spread="bootstrap" if bootstrapped else "range",
    )


def _with_interval(cell: Cell, values: dict[int, float | None], records: list[ResultRecord],
                   mode: str, measure: str | None) -> Cell:
    """The cell with its bracket: the bootstrap interval of `measure` in `mode`, or with no
    measure the seeds' range (several seeds) or nothing (one)."""
    if measure is None:
        finite = [v for v in values.values() if v is not None]
        if len(finite) < 2:
            return cell
        return replace(cell, low=min(finite), high=max(finite))
    sample = intervals.cell_sample(records, mode)
    if sample is None:
        return cell
    iv = sample.intervals().get(measure)
    if iv is None or iv.low != iv.low:
        return cell
    return replace(cell, low=iv.low, high=iv.high)


def _settings(matcher: dict[str, Any]) -> dict[str, Any]:
    """A record's matcher settings with those it predates read as their defaults
    (`EvaluationConfig.from_dict`), so records made before a setting existed and records made
    after with its default are one configuration, not two; unreadable settings as recorded."""
    from safl_bench.errors import ConfigError
    from safl_bench.matching.settings import EvaluationConfig

    try:
        return EvaluationConfig.from_dict(matcher).to_dict()
    except (ConfigError, TypeError):
        return matcher


def _matcher_notes(records: list[ResultRecord]) -> list[str]:
    from safl_bench.matching.presets import label

    configs = sorted({json.dumps(_settings(r.matcher), sort_keys=True) for r in records})
    labels = sorted({label(r.matcher) for r in records})
    if len(configs) == 1:  # the label names the preset and what was changed on top of it
        return [f"Matcher preset (all rows): {labels[0]}; its every setting, with where each "
                f"comes from: `safl-bench list matchers` (the records hold them too)."]
    return [
        f"Matcher settings differ between records ({len(configs)} configurations: "
        f"{', '.join(labels)}); see all-results.csv before comparing rows."
    ]


def _metric(name: str) -> Callable[[Metrics], float | None]:
    """Getter of a record metric by name; "recall_at_N" (N > 1) reads `recall_at_n[N]`."""
    top = re.fullmatch(r"recall_at_(\d+)", name)
    if top and top.group(1) != "1":

        def get_n(metrics: Metrics) -> float | None:
            return (metrics.recall_at_n or {}).get(top.group(1))

        return get_n

    def get(metrics: Metrics) -> float | None:
        value: float | None = getattr(metrics, name)
        return value

    return get


@dataclass(frozen=True, order=True)
class QuerySet:
    """The queries a record's measures are over (`safl_bench.evaluation.cell.scored_queries`):
    queries `first` to `last` (0-based, inclusive) of the `frames` it matched, which are the
    task's first `frames` when the matcher's `max_frames` cut it (`limited`)."""

    first: int
    last: int
    frames: int
    limited: bool

    @property
    def text(self) -> str:
        """E.g. 'queries 10–294 of the first 300 frames', 'queries 10–1135 of 1136'."""
        of = f"the first {self.frames} frames" if self.limited else str(self.frames)
        return f"queries {self.first}–{self.last} of {of}"


def query_set(record: ResultRecord) -> QuerySet | None:
    """The queries `record` was scored on, from its task spec (`n_queries`, `context_queries`)
    and matcher settings (`max_frames`, `trim_queries`); None when they cannot be read or do not
    give the record's own `n_queries` (then its count alone names them)."""
    from safl_bench.errors import ConfigError
    from safl_bench.evaluation.cell import scored_queries
    from safl_bench.matching.settings import EvaluationConfig

    spec = record.task.spec
    n, context = spec.get("n_queries"), spec.get("context_queries") or 0
    try:
        settings = EvaluationConfig.from_dict(record.matcher)
        if not isinstance(n, int) or not isinstance(context, int):
            return None
        frames = n if settings.max_frames is None else min(n, settings.max_frames)
        scored = scored_queries(frames, settings.trim_queries, context)
    except (ConfigError, TypeError):
        return None
    counts = {result.metrics.n_queries for result in record.results.values()}
    if counts != {scored.stop - scored.start}:
        return None
    return QuerySet(scored.start, scored.stop - 1, frames, frames < n)


def queries_text(record: ResultRecord) -> str:
    """The queries `record` was scored on, in words (`QuerySet.text`, else their count)."""
    queries = query_set(record)
    if queries is not None:
        return queries.text
    return f"{_count_range(m.metrics.n_queries for m in record.results.values())} queries"


def _count_range(values: Iterable[int]) -> str:
    found = sorted(set(values))
    return str(found[0]) if len(found) == 1 else f"{found[0]}–{found[-1]}"


def query_set_notes(records: Iterable[ResultRecord], column: Callable[[ResultRecord], str],
                    part: str) -> list[str]:
    """A note naming the queries a table's cells are scored on and how many have a true place
    (the recall's denominator): one line when every cell shares them, else per `part` (a
    column, or a row group such as a matcher preset) as `column(record)` names it."""
    sets: dict[str, dict[str, list[ResultRecord]]] = defaultdict(lambda: defaultdict(list))
    for r in records:
        sets[column(r)][queries_text(r)].append(r)
    if not sets:
        return []

    def said(what: str, recs: list[ResultRecord]) -> str:
        positives = _count_range(m.metrics.n_positives for r in recs for m in r.results.values())
        return f"{what}, {positives} with a true place"

    lines = {name: "; ".join(said(w, recs) for w, recs in sorted(by.items())) for name, by in sets.items()}
    if len(set(lines.values())) == 1 and all(len(by) == 1 for by in sets.values()):
        return [f"Scored queries, the same in every cell and for every method: {next(iter(lines.values()))}."]
    groups: dict[str, list[str]] = defaultdict(list)
    for name in sorted(lines):
        groups[lines[name]].append(name)
    said_per = "; ".join(f"{', '.join(names)}: {line}"
                         for line, names in sorted(groups.items(), key=lambda kv: kv[1]))
    note = f"Scored queries per {part} (not the same across {part}s: compare cells of one): {said_per}."
    if part == "preset":
        note += (" A preset's `max_frames` and `trim_queries` choose them (`safl-bench list "
                 "matchers`); each row's Matcher cell names its set.")
    return [note]


RECALL_FORMAT = ValueFormat(scale=100.0, decimals=1, better="higher")
AUC_FORMAT = ValueFormat(scale=1.0, decimals=3, better="higher")
F1_FORMAT = ValueFormat(scale=1.0, decimals=3, better="higher")
MS_FORMAT = ValueFormat(scale=1.0, decimals=2, better=None)


def paper_metric_table(
    key: TableKey,
    records: list[ResultRecord],
    *,
    metric: str,
    title: str,
    fmt: ValueFormat,
    notes: Iterable[str] = (),
) -> Table:
    """Rows = (method, version, matching mode), columns = noise conditions, values = `metric`."""
    get = _metric(metric)
    columns = condition_order(r.task.condition or "" for r in records)

    def extract(record: ResultRecord) -> Iterable[Value]:
        for mode, result in record.results.items():
            row = (record.method.name, record.method.version, mode)
            yield Value(row, record.task.condition or "", get(result.metrics), mode, metric)

    table = _build(
        key,
        records,
        title=title,
        row_header=("Method", "Version", "Matching"),
        columns=columns,
        formats=[fmt] * len(columns),
        extract=extract,
        notes=[*notes, *query_set_notes(records, lambda r: r.task.condition or "", "condition")],
    )
    return _label_modes(table)


def recall_table(key: TableKey, records: list[ResultRecord], notes: Iterable[str] = ()) -> Table:
    """The paper's Table II: recall at 100 % precision (%) per method and condition."""
    return paper_metric_table(
        key,
        records,
        metric="recall_at_100_precision",
        title="Recall at 100 % precision (%)",
        fmt=RECALL_FORMAT,
        notes=notes,
    )


def preset_table(key: TableKey, records: list[ResultRecord], *, metric: str = "recall_at_100_precision",
                 title: str = "Sequence matcher by preset: recall at 100 % precision (%)",
                 notes: Iterable[str] = ()) -> Table:
    """Rows = (method, version, matcher preset and its scored queries), columns = noise
    conditions, values = `metric` of the sequence matcher: how much of a Table II cell comes from
    the matcher's variant. `records` may hold several presets' records of one task (from separate
    results folders). A preset's evaluation settings (`max_frames`, `trim_queries`) choose the
    queries it scores, so each row names its query set (`QuerySet`) and a note gives each set's
    count: a column holds rows scored on different queries, ranked only within one preset."""
    from safl_bench.matching.presets import label

    get = _metric(metric)
    columns = condition_order(r.task.condition or "" for r in records)

    def extract(record: ResultRecord) -> Iterable[Value]:
        result = record.results.get("sequence")
        if result is not None:
            matcher = f"{label(record.matcher)} · {queries_text(record)}"
            yield Value((record.method.name, record.method.version, matcher),
                        record.task.condition or "", get(result.metrics), "sequence", metric)

    table = _build(key, records, title=title,
                   row_header=("Method", "Version", "Matcher · scored queries"),
                   columns=columns, formats=[RECALL_FORMAT] * len(columns), extract=extract,
                   notes=[*notes, *query_set_notes(records, lambda r: label(r.matcher), "preset")])
    table.notes = [n for n in table.notes if not n.startswith("Matcher settings differ")]
    table.notes.append("Each preset's every setting: `safl-bench list matchers`.")
    return table


def recall_at_1_table(key: TableKey, records: list[ResultRecord], notes: Iterable[str] = ()) -> Table:
    """Recall@1 (%) per method and condition: the fraction of queries with a true place whose
    reported match is one (single-frame: the nearest database frame)."""
    return paper_metric_table(
        key, records, metric="recall_at_1", title="Recall@1 (%)", fmt=RECALL_FORMAT, notes=notes
    )


def auc_table(key: TableKey, records: list[ResultRecord], notes: Iterable[str] = ()) -> Table:
    """The AUC of the ROC curve per method and condition (the paper's Figure 13 as a table)."""
    return paper_metric_table(
        key, records, metric="auc", title="ROC AUC", fmt=AUC_FORMAT, notes=notes
    )


#: Clauses of `Timings.how_run` that say which run timed a record (`safl_bench.run.runner`), not
#: how it was timed: the time table's note leaves them to the records.
_PROVENANCE = ("timed by the run of ", "rescored with metrics version ", "the cell's timing ")


def time_table(key: TableKey, records: list[ResultRecord], notes: Iterable[str] = ()) -> Table:
    """The paper's Table III: feature inference time per frame (ms, batch 1, median).

    A cell's timing is the mean of its seeds' distinct timings on the host of its lowest seed:
    seeds run later on another host (CPU model or vector instruction sets) carry that host's
    timing, and a mean over hosts is no host's speed. Such cells are named in a note, and their
    other-host seeds are left out of this table only. A run times a (method, task) cell once and
    its other seeds' records carry that timing (`Timings`): equal timings are one measurement, so
    such a cell shows its one timing marked `ONE_TIMING`, never a bracket of zero width
    (`_timing_cell`)."""
    columns = condition_order(r.task.condition or "" for r in records)
    first: dict[tuple[str, str, str], ResultRecord] = {}
    hosts: dict[tuple[str, str, str], set[str]] = defaultdict(set)
    for r in records:
        cell = (r.method.name, r.method.version, r.task.id)
        if cell not in first or r.seed < first[cell].seed:
            first[cell] = r
        hosts[cell].add(_machine(r))

    def extract(record: ResultRecord) -> Iterable[Value]:
        row = (record.method.name, record.method.version, "")
        yield Value(row, record.task.condition or "", record.timings.describe_ms_per_frame)

    def on_first_host(record: ResultRecord) -> bool:
        return _machine(record) == _machine(first[(record.method.name, record.method.version,
                                                   record.task.id)])

    machines = sorted({_machine(r) for r in first.values()})
    how = sorted({clause for r in first.values() for clause in r.timings.how_run.split("; ")
                  if not clause.startswith(_PROVENANCE)})
    extra = [
        "Describing one map at a time (batch 1), median over repeats; matching time excluded. "
        "A cell is the mean of its seeds' distinct timings on its lowest seed's host.",
        f"Measured on: {'; '.join(machines)}. Runs: {'; '.join(how)} (each record's "
        "`timings.how_run` says which run timed it).",
    ]
    if len(machines) > 1:
        extra.append("Rows were timed on different machines: compare them with care.")
    extra += _carried_note([r for r in records if on_first_host(r)])
    extra += _loaded_note([r for r in records if on_first_host(r)])
    mixed: dict[tuple[str, str, tuple[str, ...]], list[str]] = defaultdict(list)
    for (name, version, task), seen in hosts.items():
        if len(seen) > 1:
            mixed[(name, version, tuple(sorted(seen)))].append(first[(name, version, task)]
                                                              .task.condition or task)
    if mixed:
        extra.append(
            "Seeds of one cell timed on different machines (the cell is its lowest seed's host's; "
            "the other seeds' timings are left out): "
            + "; ".join(f"{name} v{version}, {', '.join(condition_order(cells))}: "
                        f"{' / '.join(seen)}" for (name, version, seen), cells in sorted(mixed.items()))
            + ".")
    table = _build(
        key,
        [r for r in records if on_first_host(r)],
        title="Feature inference time per frame (ms)",
        row_header=("Method", "Version", ""),
        columns=columns,
        formats=[MS_FORMAT] * len(columns),
        extract=extract,
        notes=[*notes, *extra],
        fewer_seeds="its other seeds were not run, or were timed on another host (see the note on hosts).",
        combine=_timing_cell,
    )
    table.spread = "timings"
    return table


def _timing_cell(values: dict[int, float | None]) -> Cell | None:
    """A time-table cell: the mean of its seeds' distinct timings and, with two or more, their
    lowest and highest; `measurements` says how many there are. Equal values are one
    measurement carried by several records (a median of timed repeats does not repeat to the
    last bit by chance), so a cell timed once is that one timing, not an interval."""
    if not values:
        return None
    seeds = frozenset(values)
    if any(v is None for v in values.values()):
        return Cell(mean=None, seeds=seeds)
    distinct = sorted({float(v) for v in values.values() if v is not None})
    mean = float(np.mean(np.asarray(distinct, dtype=np.float64)))
    if len(distinct) == 1:
        return Cell(mean=mean, seeds=seeds, measurements=1)
    return Cell(mean=mean, low=distinct[0], high=distinct[-1], seeds=seeds,
                measurements=len(distinct))


#: What a record's `timings.how_run` says when it carries the timing of another seed of its cell.
CARRIED = "measured at seed "


def _loaded_note(records: list[ResultRecord]) -> list[str]:
    """A note on the timings taken under load (`timed_under_load`): how many of the records
    that say, which cells; [] when none was, and a line on the records that do not say."""
    said = [r for r in records if timed_under_load(r) is not None]
    loaded = sorted({f"{r.method.name}@{r.method.version} {r.task.condition or r.task.id}"
                     for r in said if timed_under_load(r)})
    out = []
    if loaded:
        out.append(f"{len(loaded)} cell(s) were timed while the 1-minute load average exceeded "
                   f"the host's cores, so other work shared the CPUs and their ms/frame "
                   f"overstates the method's: {', '.join(loaded)}.")
    if said and len(said) < len(records):
        out.append(f"{len(records) - len(said)} of the {len(records)} records predate the "
                   "load average in records: whether they were timed under load is not known.")
    return out


def _carried_note(records: list[ResultRecord]) -> list[str]:
    """A note on the cells whose seeds share one timing: how many, and why (from the records'
    `timings.how_run`); [] when every seed of every cell was timed on its own."""
    by_cell: dict[tuple[str, str, str], list[ResultRecord]] = defaultdict(list)
    for r in records:
        by_cell[(r.method.name, r.method.version, r.task.id)].append(r)
    shared = carried = 0
    for recs in by_cell.values():
        timings = [r.timings.describe_ms_per_frame for r in recs]
        if len(recs) < 2 or len(set(timings)) == len(timings):
            continue
        shared += 1
        # every record of a repeated timing but one says it carries it
        repeats = len(timings) - len(set(timings))
        carried += sum(CARRIED in r.timings.how_run for r in recs) >= repeats
    if not shared:
        return []
    why = ("the run timed the method at batch 1 once per (method, task), at the first seed it "
           "computed, and the other seeds' records carry that timing (their `timings.how_run` "
           "says \"the cell's timing …, measured at seed S\"); each seed's matches and scores are "
           "its own")
    if carried < shared:
        why += (f"; in {shared - carried} of them records that do not say so hold the same "
                "timing to the last digit, counted once as well")
    return [f"{shared} of {len(by_cell)} cells were timed once for all their seeds: {why}. Such "
            f"a cell shows its one timing, marked '{ONE_TIMING}', not a range."]


def _machine(record: ResultRecord) -> str:
    """The host a record was timed on, as the time table names it."""
    env = record.environment
    vector = env.cpu_vector or "vector sets not recorded"
    return f"{env.cpu_model} ({env.cpu_cores} cores; {vector})"


Metric = tuple[str, str, ValueFormat]

REVISIT_METRICS: tuple[Metric, ...] = (
    ("f1_max", "F1max", F1_FORMAT),
    ("recall_at_100_precision", "R@100%P (%)", RECALL_FORMAT),
    ("auc", "AUC", AUC_FORMAT),
    ("recall_at_1", "R@1 (%)", RECALL_FORMAT),
)
BEVPLACE_METRICS: tuple[Metric, ...] = (
    ("recall_at_1", "R@1 (%)", RECALL_FORMAT),
    ("recall_at_5", "R@5 (%)", RECALL_FORMAT),
    ("recall_at_10", "R@10 (%)", RECALL_FORMAT),
    ("f1_max", "F1max", F1_FORMAT),
)

#: Recall@1 (%) on KITTI 00 / 02 / 05 / 06 under BEVPlace's protocol, as BEVPlace's paper (Luo
#: et al., ICCV 2023) publishes them; shown beside the measured rows, never mixed with them.
PUBLISHED_BEVPLACE: dict[str, tuple[float, float, float, float]] = {
    "BEVPlace": (99.7, 98.1, 99.3, 100.0),
    "ResNet18+NetVLAD": (95.9, 83.2, 90.3, 98.5),
    "OverlapTransformer": (96.7, 80.1, 91.9, 95.6),
}
PUBLISHED_SEQUENCES = ("00", "02", "05", "06")


def sequence_table(key: TableKey, records: list[ResultRecord], metrics: tuple[Metric, ...], title: str,
                   notes: Iterable[str] = ()) -> Table:
    """Rows = (method, version, matching mode), columns = `metrics` per sequence."""
    sequences = sorted({r.task.sequence for r in records})
    columns: list[str] = []
    formats: list[ValueFormat] = []
    for sequence in sequences:
        for _, label, fmt in metrics:
            columns.append(f"{sequence} {label}")
            formats.append(fmt)

    def extract(record: ResultRecord) -> Iterable[Value]:
        for mode, result in record.results.items():
            row = (record.method.name, record.method.version, mode)
            for metric, label, _ in metrics:
                yield Value(row, f"{record.task.sequence} {label}", _metric(metric)(result.metrics),
                            mode, metric)

    table = _build(
        key,
        records,
        title=title,
        row_header=("Method", "Version", "Matching"),
        columns=columns,
        formats=formats,
        extract=extract,
        notes=[*notes, *query_set_notes(records, lambda r: r.task.sequence, "sequence")],
    )
    return _label_modes(table)


def revisit_table(key: TableKey, records: list[ResultRecord], notes: Iterable[str] = ()) -> Table:
    """Revisit protocol: F1max, recall at 100 % precision, AUC and Recall@1 per method and sequence."""
    return sequence_table(key, records, REVISIT_METRICS,
                          "Revisit protocol: F1max, recall at 100 % precision, AUC, Recall@1", notes)


def bevplace_table(key: TableKey, records: list[ResultRecord], notes: Iterable[str] = ()) -> Table:
    """BEVPlace's protocol: Recall@1/5/10 (single-frame: the nearest database frames; sequence:
    the matcher's one answer, R@1 only) and F1max per method and sequence."""
    return sequence_table(key, records, BEVPLACE_METRICS,
                          "BEVPlace's protocol: Recall@1, @5, @10 and F1max", notes)


def published_bevplace_markdown(level: int = 3) -> str:
    """BEVPlace's published Recall@1 rows as a Markdown table, marked as not run here."""
    lines = [
        f"{'#' * level} Published Recall@1 (%), BEVPlace's protocol (not run here)",
        "",
        "From BEVPlace's paper (Luo et al., ICCV 2023, Table 1), as published; not computed by "
        "safl-bench. Compare with the single-frame R@1 above.",
        "",
        "| Method | " + " | ".join(PUBLISHED_SEQUENCES) + " |",
        "|---|" + "---:|" * len(PUBLISHED_SEQUENCES),
    ]
    for name, values in PUBLISHED_BEVPLACE.items():
        lines.append(f"| {name} (published) | " + " | ".join(f"{v:.1f}" for v in values) + " |")
    return "\n".join(lines) + "\n"


def _label_modes(table: Table) -> Table:
    """Show matching modes by their reader-facing names ('single-frame')."""
    table.rows = [(m, v, MODE_LABELS.get(mode, mode)) for m, v, mode in table.rows]
    return table


def all_results_frame(records: Iterable[ResultRecord]) -> pd.DataFrame:
    """Every record and matching mode as one row with all metrics and timings (long format)."""
    from safl_bench.matching.presets import label

    rows = []
    for r in sorted(records, key=lambda rec: rec.key):
        for mode in sorted(r.results, key=MODES.index):
            m = r.results[mode].metrics
            rows.append(
                {
                    "source": r.task.source_label,
                    "source_kind": r.task.source_kind,
                    "protocol": r.task.protocol,
                    "task": r.task.id,
                    "task_version": r.task.version,
                    "sequence": r.task.sequence,
                    "condition": r.task.condition or "",
                    "spec_fingerprint": r.task.spec_fingerprint,
                    "method": r.method.name,
                    "method_version": r.method.version,
                    # "shipped", "untrained" (random networks), "file", or "" (nothing learned)
                    "weights": str((r.method.params.get("weights") or {}).get("source", "")),
                    "seed": r.seed,
                    "matching": MODE_LABELS[mode],
                    "recall_at_100_precision": _num(m.recall_at_100_precision, 4),
                    "auc": _num(m.auc, 4),
                    "f1_max": _num(m.f1_max, 4),
                    "extended_precision": _num(m.extended_precision, 4),
                    "recall_at_1": _num(m.recall_at_1, 4),
                    **{f"recall_at_{n}": _num((m.recall_at_n or {}).get(n), 4) for n in ("5", "10")},
                    "recall_at_100_precision_of_correct": _num(
                        m.recall_at_100_precision_of_correct, 4),
                    "f1_max_of_correct": _num(m.f1_max_of_correct, 4),
                    "extended_precision_of_correct": _num(m.extended_precision_of_correct, 4),
                    "authors_recall_at_99p": _num(m.authors_recall_at_99p, 4),
                    "n_queries": m.n_queries,
                    "n_scored": UNDEFINED if m.n_scored is None else m.n_scored,
                    "n_positives": m.n_positives,
                    "n_correct": UNDEFINED if m.n_correct is None else m.n_correct,
                    # of the scored queries with a true place, the share it answered (None:
                    # no per-query outcomes); the board never ranks a cell under ANSWERED_MIN
                    "answered_share": _num(_answered([r], mode), 4),
                    "metrics_version": r.metrics_version,
                    "describe_ms_per_frame": _num(r.timings.describe_ms_per_frame, 3),
                    "describe_frames_per_s": _num(r.timings.describe_frames_per_s, 1),
                    "matcher_s": _num(r.timings.matcher_s, 3),
                    "peak_memory_mb": _num(r.timings.peak_memory_mb, 1),
                    "how_run": r.timings.how_run,
                    "matcher_preset": label(r.matcher),
                    "matcher": json.dumps(r.matcher, sort_keys=True),
                    "cpu": r.environment.cpu_model,
                    "git_revision": r.environment.git_revision,
                    # the superseded task whose record's matches this one keeps (`results.derive`)
                    "derived_from": "" if r.derived_from is None else r.derived_from.task,
                }
            )
    return pd.DataFrame(rows)


def _num(value: float | None, decimals: int) -> str:
    return UNDEFINED if value is None else f"{value:.{decimals}f}"


def frame_csv(frame: pd.DataFrame) -> str:
    """CSV text of a frame ('\\n' line ends, no index)."""
    buffer = io.StringIO()
    frame.to_csv(buffer, index=False, lineterminator="\n")
    return buffer.getvalue()
