"""The guides' generated blocks: record-derived numbers in docs/guides/*.md that `safl-bench
leaderboard` rewrites between markers, as it does the README's (`readme.replace_block`), so a
regeneration keeps the guides' numbers true and a test checks they are what the records give.

`BLOCKS` names each block: the guide (relative to the checkout), its markers and the function
that writes it from the leaderboard's `BuildReport`; a block whose table the records do not
give is left as it is (`update_guides` skips it). Each block is a table of the leaderboard
(`Table.markdown`, the same text as the tables folder) or counted from one (`table2.Row`), never
a number typed by hand.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from safl_bench.leaderboard import table2
from safl_bench.leaderboard.headline import facts_markdown
from safl_bench.leaderboard.readme import replace_block
from safl_bench.leaderboard.report import BuildReport, PublishedTable
from safl_bench.leaderboard.tables import MODE_LABELS, Table
from safl_bench.results.records import ResultRecord

GENERATED = "<!-- written by `safl-bench leaderboard` from the leaderboard's records; do not edit -->"

#: The label under which `build` publishes Table II's recall table and the revisit table.
RECALL_LABEL = "Recall at 100 % precision (Table II)"
REVISIT_LABEL = "F1max, recall at 100 % precision, AUC, Recall@1"


@dataclass(frozen=True)
class Block:
    """One generated block of a guide."""

    guide: str  # path relative to the checkout's root
    name: str  # the markers are <!-- name:start --> and <!-- name:end -->
    write: Callable[[BuildReport], str | None]  # the block's text between its markers; None: none

    @property
    def start(self) -> str:
        return f"<!-- {self.name}:start -->"

    @property
    def end(self) -> str:
        return f"<!-- {self.name}:end -->"

    def text(self, report: BuildReport) -> str | None:
        """The block with its markers, or None when the records give no table for it."""
        body = self.write(report)
        if body is None:
            return None
        return "\n".join([self.start, GENERATED, "", body.rstrip("\n"), self.end])


def _newest(report: BuildReport, source_kind: str, protocol: str, label: str,
            sequence: str = "") -> PublishedTable | None:
    """The published table of `label` for that source and protocol, of the newest task version."""
    found = [t for t in report.tables if t.key.source_kind == source_kind and t.key.protocol == protocol
             and t.label == label and t.key.sequence == sequence]
    return max(found, key=lambda t: t.key.task_version, default=None)


def _queries_note(table: Table) -> list[str]:
    return [f"- {note}" for note in table.notes if note.startswith("Scored queries")]


def synthetic_table_ii(report: BuildReport) -> str | None:
    """Table II's recall on the synthetic default, sequence 00, newest task version: the
    leaderboard's table without its notes but the one on the scored queries."""
    published = _newest(report, "synth", "paper", RECALL_LABEL, "00")
    if published is None:
        return None
    table = published.table
    bare = dataclasses.replace(table, notes=[])
    return "\n".join([facts_markdown(table, published.records), "",
                      bare.markdown(level=4).rstrip("\n"), "", *_queries_note(table)])


def synthetic_revisit(report: BuildReport) -> str | None:
    """The revisit protocol on the synthetic default, newest task version: per method, version
    and sequence, each measure as 'sequence matcher / single frame'."""
    published = _newest(report, "synth", "revisit", REVISIT_LABEL)
    if published is None:
        return None
    table = published.table
    sequences = sorted({c.split(" ", 1)[0] for c in table.columns})
    measures = list(dict.fromkeys(c.split(" ", 1)[1] for c in table.columns))
    modes = [MODE_LABELS[m] for m in ("sequence", "single_frame")]
    lines = [facts_markdown(table, published.records), "",
             f"Each cell: {' / '.join(modes)} matching, {table_sentence(table)}", "",
             "| Method | Version | Sequence | " + " | ".join(measures) + " |",
             "|---|---|---|" + "---:|" * len(measures)]
    methods = sorted({(row[0], row[1]) for row in table.rows},
                     key=lambda mv: next(i for i, r in enumerate(table.rows) if r[:2] == mv))
    for name, version in methods:
        for sequence in sequences:
            values = []
            for measure in measures:
                j = table.columns.index(f"{sequence} {measure}")
                shown = []
                for mode in modes:
                    i = table.rows.index((name, version, mode)) if (name, version, mode) in table.rows else None
                    shown.append("—" if i is None else table.value_text(table.cells[i][j], table.formats[j]))
                values.append(" / ".join(shown))
            lines.append(f"| {name} | {version} | {sequence} | " + " | ".join(values) + " |")
    return "\n".join([*lines, "", *_queries_note(table)])


def table_sentence(table: Table) -> str:
    """What a compact block's values are: means over which seeds (the intervals are in the
    leaderboard's table)."""
    seeds = sorted(table.seeds)
    over = f"seed {seeds[0]}" if len(seeds) == 1 else f"mean over seeds {', '.join(map(str, seeds))}"
    return f"{over}; intervals and ranks in the leaderboard's table."


def table_ii_summary(report: BuildReport) -> str | None:
    """Table II side by side in counts: per row of ours (method, version, weights), in how many
    conditions the paper's value lies inside our interval under each measure and which cells
    those are; then the paper's order per pair of rows."""
    if not report.table2:
        return None
    rows, rel = report.table2[min(report.table2)]
    groups: dict[tuple[str, str, str], list[table2.Row]] = {}
    for row in rows:
        groups.setdefault((row.method, row.version, row.weights), []).append(row)
    (ours, _), (authors, _) = table2.MEASURES
    lines = ["| Method | Version | Weights | inside, ours | inside, authors' reading | "
             "cells inside, ours: ours [interval] against the paper |",
             "|---|---|---|---:|---:|---|"]
    for (method, version, weights), cells in groups.items():
        judged = {m: [c for c in cells if c.inside(m) is not None] for m in (ours, authors)}
        inside = {m: [c for c in judged[m] if c.inside(m)] for m in (ours, authors)}
        which = "; ".join(f"{c.condition} {_format(c, ours)} against {c.paper:.1f}" for c in inside[ours])
        lines.append(f"| {table2.PAPER_NAMES[method].split(' (')[0]} | {version} | {weights} | "
                     f"{len(inside[ours])} of {len(judged[ours])} | "
                     f"{len(inside[authors])} of {len(judged[authors])} | {which or 'none'} |")
    return "\n".join([
        "Per row of ours, in how many of its conditions the paper's value lies inside our 95 % "
        "interval (mean over seeds, `authors`/`authors-sad` presets, sequence matching), under "
        "our measure and the authors' reading:", "", *lines, "",
        "The paper's order Stable-AFL > BiGAN > SAD, per pair of rows over the conditions both "
        "have (our measure; overlapping intervals are a tie):", "",
        *table2._order_table(rows), "",
        f"Cell by cell, both measures: `leaderboard/{rel}`."])


def _format(row: table2.Row, measure: str) -> str:
    iv = row.ours.get(measure)
    return "not run" if iv is None else iv.format(100.0)


def _mean(iv: object) -> str:
    from safl_bench.evaluation.uncertainty import Interval

    return "—" if not isinstance(iv, Interval) else iv.format(100.0).split(" [")[0]


def table_ii_variants(report: BuildReport) -> str | None:
    """What each measured change (the Table II variants, `leaderboard/experiments/table2/`)
    gives on each condition, beside the row it changes, our measure; then the paper's order
    with the changed rows in place of the rows they change."""
    if not report.table2 or not report.table2_variants:
        return None
    rows, rel = report.table2[min(report.table2)]
    measure = table2.MEASURES[0][0]
    lines = ["| Change | Method | Version | " + " | ".join(table2.CONDITIONS) + " |",
             "|---|---|---|" + "---:|" * len(table2.CONDITIONS)]
    orders: list[str] = []
    for variant in report.table2_variants:
        changed: list[table2.Row] = []
        keys = sorted({(r.method.name, r.method.version) for r in variant.records},
                      key=lambda mv: (table2.PAPER_ORDER.index(mv[0]) if mv[0] in table2.PAPER_ORDER else 9, mv[1]))
        for name, version in keys:
            if name not in table2.PAPER_NAMES:
                continue
            base = {r.condition: r for r in rows if r.method == name and r.version == version
                    and "selected on the test set" not in r.weights and "iterations" not in r.weights}
            cells = []
            for condition in table2.CONDITIONS:
                found = variant.cell(name, version, condition)
                iv = None if found is None else found.get(measure)
                before = base.get(condition)
                cells.append(f"{_mean(before.ours.get(measure) if before else None)} → {_mean(iv)}")
                if iv is not None and before is not None:
                    changed.append(dataclasses.replace(before, ours={**before.ours, measure: iv},
                                                       weights=f"{before.weights}; `{variant.name}`"))
            lines.append(f"| `{variant.name}`: {variant.label} | {table2.PAPER_NAMES[name].split(' (')[0]} | "
                         f"{version} | " + " | ".join(cells) + " |")
        ids = {(r.method, r.version, r.weights) for r in changed}
        names = {r.method for r in changed}
        kept = [r for r in rows if r.method not in names]
        for order in table2.order_counts([*kept, *changed], measure):
            if order.upper in ids or order.lower in ids:
                orders.append(f"| {_order_name(order.upper)} | {_order_name(order.lower)} | "
                              f"{order.holds} | {order.tied} | {order.reversed} |")
    return "\n".join([
        "Each change measured on the twelve conditions (records under "
        "`leaderboard/experiments/table2/<change>/`, the same seeds and presets as the rows above; "
        "our measure, mean over seeds): the row as the leaderboard has it → with the change.", "",
        *lines, "",
        "The paper's order with a changed row in place of the row it changes (our measure; "
        "overlapping intervals are a tie):", "",
        "| The paper's order: above | below | holds | tied | reversed |", "|---|---|---:|---:|---:|",
        *orders, "",
        f"Every cell outside its interval, with what each change gives there and its interval: "
        f"`leaderboard/{rel}`."])


def _order_name(key: tuple[str, str, str]) -> str:
    return f"{table2.PAPER_NAMES[key[0]].split(' (')[0]} @{key[1]} ({key[2]})"


#: The label under which `build` publishes BEVPlace's protocol table.
BEVPLACE_LABEL = "Recall@1/5/10, F1max"


def bevplace_reproduction(report: BuildReport) -> str | None:
    """BEVPlace's protocol, newest task version on real KITTI top views: Recall@1 per method,
    version and sequence, single frame (with the count of queries it matched, of those with a
    true place) and with the sequence matcher, beside BEVPlace's published values; one table per
    reading of the images that has records (the plain images first, then the rotated ones,
    `safl_bench.sources.bev.ROTATED_LABELS`), so that which images give the published figures
    can be read off."""
    found = [t for t in report.tables if t.key.source_kind == "bev" and t.key.protocol == "bevplace"
             and t.label == BEVPLACE_LABEL]
    if not found:
        return None
    newest: dict[str, PublishedTable] = {}
    for t in found:
        if t.key.source_label not in newest or t.key.task_version > newest[t.key.source_label].key.task_version:
            newest[t.key.source_label] = t
    from safl_bench.sources.bev import BEV_LABEL

    parts = [_bevplace_reading(newest[label], several=len(newest) > 1)
             for label in sorted(newest, key=lambda label: (label != BEV_LABEL, label))]
    return "\n\n".join(parts)


def _bevplace_reading(published: PublishedTable, several: bool) -> str:
    """`bevplace_reproduction`'s table for one reading of the images (one source label)."""
    from safl_bench.leaderboard.tables import (
        PUBLISHED_BEVPLACE,
        PUBLISHED_SEQUENCES,
        UNTRAINED_MARK,
    )
    from safl_bench.methods.training_data import record_seen, record_untrained, seen_mark

    table = published.table
    sequences = sorted({r.task.sequence for r in published.records})
    by: dict[tuple[str, str, str], list[ResultRecord]] = {}
    for r in published.records:
        version = r.method.version + seen_mark(record_seen(r))
        version += UNTRAINED_MARK if record_untrained(r) else ""
        by.setdefault((r.method.name, version, r.task.sequence), []).append(r)
    seeds = sorted({r.seed for r in published.records})
    header = "| Method | Version | " + " | ".join(
        f"{s} single frame | {s} sequence" for s in sequences) + " |"
    lines = [header, "|---|---|" + "---:|---:|" * len(sequences)]
    for name, values in PUBLISHED_BEVPLACE.items():
        if name == "BEVPlace":
            shown = [f"{values[PUBLISHED_SEQUENCES.index(s)]:.1f}" if s in PUBLISHED_SEQUENCES else "—"
                     for s in sequences]
            lines.append("| BEVPlace (published) | — | " + " | ".join(f"{v} | —" for v in shown) + " |")
    versions = list(dict.fromkeys((row[0], row[1]) for row in table.rows))
    for name, version in versions:
        cells = []
        for sequence in sequences:
            recs = by.get((name, version, sequence), [])
            for mode in ("single_frame", "sequence"):
                results = [r.results[mode].metrics for r in recs if mode in r.results]
                if not results:
                    cells.append("—")
                    continue
                if any(m.n_correct is None or m.n_positives is None for m in results):
                    known = [m.recall_at_1 for m in results if m.recall_at_1 is not None]
                    cells.append(f"{100.0 * sum(known) / len(known):.1f}" if known else "n/a")
                    continue
                correct = sum(int(m.n_correct or 0) for m in results)
                positives = sum(int(m.n_positives or 0) for m in results)
                text = f"{100.0 * correct / positives:.1f}" if positives else "n/a"
                cells.append(f"{text} ({correct} of {positives})" if mode == "single_frame" else text)
        lines.append(f"| {name} | {version} | " + " | ".join(cells) + " |")
    over = f"seed {seeds[0]}" if len(seeds) == 1 else f"seeds {', '.join(map(str, seeds))} pooled"
    images = f"**{published.key.source_label}**: " if several else ""
    return "\n".join([
        f"{images}BEVPlace's protocol, task version v{published.key.task_version}, Recall@1 (%) over the "
        f"scored queries with a true place, {over}: single frame (the nearest database frame; in "
        "brackets the queries it matched within the true-place radius, of those with a true place) "
        "and with the paper's sequence matcher; BEVPlace's published values (Luo et al., ICCV 2023, "
        "Table 1) are single frame:", "", *lines, "", *_queries_note(table), "",
        f"Intervals, Recall@5 and @10 and F1max: `leaderboard/{published.md}`."])


#: Every generated block of the guides.
BLOCKS: tuple[Block, ...] = (
    Block("docs/guides/leaderboard.md", "synthetic-table2", synthetic_table_ii),
    Block("docs/guides/leaderboard.md", "synthetic-revisit", synthetic_revisit),
    Block("docs/guides/reproduce-table-ii.md", "table2-summary", table_ii_summary),
    Block("docs/guides/reproduce-table-ii.md", "table2-variants", table_ii_variants),
    Block("docs/guides/reproduce-bevplace.md", "bevplace-reproduction", bevplace_reproduction),
)


def blocks(report: BuildReport, which: Sequence[Block] = BLOCKS) -> list[tuple[Block, str]]:
    """Each block the records give, with its text (markers included)."""
    out = []
    for block in which:
        text = block.text(report)
        if text is not None:
            out.append((block, text))
    return out


def update_guides(root: str | Path, report: BuildReport, which: Sequence[Block] = BLOCKS) -> list[Path]:
    """Rewrite the generated blocks of the guides under the checkout `root` (a guide without the
    markers, or missing, is left alone); the guides that changed."""
    changed: list[Path] = []
    for block, text in blocks(report, which):
        path = Path(root) / block.guide
        if path.is_file() and replace_block(path, block.start, block.end, text, block.name):
            changed.append(path)
    return sorted(set(changed))
