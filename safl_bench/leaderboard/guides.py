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


#: Every generated block of the guides.
BLOCKS: tuple[Block, ...] = (
    Block("docs/guides/leaderboard.md", "synthetic-table2", synthetic_table_ii),
    Block("docs/guides/leaderboard.md", "synthetic-revisit", synthetic_revisit),
    Block("docs/guides/reproduce-table-ii.md", "table2-summary", table_ii_summary),
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
