"""The paper's Table II beside ours: each published cell against our mean and 95 % interval.

`PUBLISHED` is the paper's Table II ("Recall at 100 % precision", /work/shared/paper: the
markdown of the paper, its TABLE II), the twelve conditions in the paper's column order, in
percent, for its three methods (the paper's "Stable-ALI" row is this project's ``stable_afl``).
The paper's text gives SAD 44.5 % at T1R1, which is its table's T5R1 value; the table's 28.3 is
kept (the table is what it calls Table II).

`side_by_side` reads the records of the real-KITTI 00 top views (``bev-paper``) made under the
authors' paper-era presets - ``authors`` for the learned methods, ``authors-sad`` for SAD
(`safl_bench.matching.presets`) - and puts, per method and condition, the paper's value beside
ours under two measures: recall at exactly 100 % precision over every query with a true place
(``recall_at_100_precision``, ours) and the authors' reading (``authors_recall_at_99p``: recall
over correct matches at the first precision >= 0.99). Each is the mean over the cell's seeds
with the 95 % interval over seeds and queries (`safl_bench.evaluation.uncertainty`, the same bootstrap as
every other table), and says whether the paper's value lies inside it (the paper prints one
decimal, so an interval is widened by that rounding, 0.05 points, on each side).

Rows are per method, version and weights (`weights_text`: the data they were trained on, how
many iterations, and which checkpoint: the last one, or the one the authors' way of choosing
picks, the best on 00, marked as selected on the test set: `selected`, records kept out of
every other table).

What explains a cell outside its interval is read from experiments, not written by hand:
`Variant`s are record sets of the same tasks with one thing changed (their `label` says what;
`load_variants` reads them from folders with a `variant.json`), and the table's other rows of the
same method and condition (another version, another checkpoint) count as such changes too.
`causes` gives one line per row outside its interval: each change measured on that cell, its
mean [interval], and whether it holds the paper's value; a cell that no change brings onto the
paper's value says so. `orders` counts, per condition, whether the paper's order holds between
the methods' rows (non-overlapping intervals: an order; overlapping: a tie).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from safl_bench.evaluation.uncertainty import Interval
from safl_bench.leaderboard import intervals
from safl_bench.results.records import Problem, ResultRecord, load_records

#: Table II's columns, in the paper's order.
CONDITIONS = ("T1R1", "T5R1", "T10R1", "T20R1", "T1R1.5", "T5R1.5", "T10R1.5", "T20R1.5",
              "T1R2", "T5R2", "T10R2", "T20R2")

#: The paper's Table II, recall at 100 % precision in percent, per method and condition.
PUBLISHED: dict[str, dict[str, float]] = {
    name: dict(zip(CONDITIONS, values, strict=True)) for name, values in (
        ("sad", (28.3, 44.5, 12.4, 0.8, 1.3, 0.8, 0.9, 2.1, 0.2, 0.1, 0.0, 0.0)),
        ("bigan", (51.9, 19.8, 35.7, 19.8, 26.5, 3.8, 9.1, 15.4, 44.2, 8.6, 4.2, 1.8)),
        ("stable_afl", (90.9, 58.4, 46.1, 15.4, 58.1, 12.5, 15.6, 16.5, 45.3, 7.5, 10.8, 4.9)),
    )
}

#: The paper's names of the methods, in its row order.
PAPER_NAMES = {"sad": "SAD", "bigan": "BiGAN", "stable_afl": "Stable-ALI (stable_afl)"}
#: Where the row name "Stable-ALI" comes from (the paper's Table II, and its text on Figure 13;
#: its title, abstract and Figure 12 say Stable-AFL).
PAPER_NAME_NOTE = ("\"Stable-ALI\" is the paper's own name for its method in Table II (and in its "
                   "text on Figure 13; its title and Figure 12 say Stable-AFL): here `stable_afl`.")

#: The matcher preset each method's row is read under (the authors' paper-era code).
PRESET_OF = {"sad": "authors-sad", "bigan": "authors", "stable_afl": "authors"}

#: The measures beside the paper's value: (record measure, column title).
MEASURES = (("recall_at_100_precision", "ours: R@100%P over positives"),
            ("authors_recall_at_99p", "authors' reading: R over correct at P>=0.99"))

#: The task family the table reads: real KITTI 00 top views, the paper protocol.
SOURCE_KIND, SEQUENCE = "bev", "00"


@dataclass(frozen=True)
class Row:
    """One cell of Table II: the paper's value and ours (per measure, None where no records)."""

    method: str
    version: str
    condition: str
    paper: float
    ours: dict[str, Interval | None]
    seeds: tuple[int, ...]
    weights: str = "none"

    def inside(self, measure: str) -> bool | None:
        """Whether the paper's value lies in our interval of `measure` (None: no interval)."""
        iv = self.ours.get(measure)
        if iv is None or iv.low != iv.low:
            return None
        return iv.low * 100 - 0.05 <= self.paper <= iv.high * 100 + 0.05


def weights_text(record: ResultRecord) -> str:
    """What a record's weights are, in words: training data, iterations, checkpoint ("none"
    for methods without weights)."""
    from safl_bench.methods.training_data import trained_on

    config: dict[str, Any] = record.method.params
    info = config.get("weights")
    if not isinstance(info, dict) or info.get("source") == "untrained":
        return "none" if not isinstance(info, dict) else "untrained"
    data = trained_on(info)
    raw = info.get("trained_on")
    stored: dict[str, Any] = raw if isinstance(raw, dict) else {}
    parts = []
    if data is not None:
        every = "" if data.step == 1 else f" every {data.step}th frame"
        parts.append(data.describe().replace(", ", "+") + every)  # "KITTI 00 frames 0–2999"
    steps = stored.get("steps", (config.get("params") or {}).get("iterations"))
    if isinstance(steps, int):
        parts.append(f"{steps} iterations")
    if stored.get("selected_on"):
        parts.append("best on 00, selected on the test set")
    elif isinstance(steps, int):
        parts.append("last checkpoint")
    return ", ".join(parts) or str(info.get("source", "weights"))


def _selected(records: Sequence[ResultRecord]) -> dict[tuple[str, str, str, str], list[ResultRecord]]:
    """The records of each (method, version, weights, condition) under that method's preset
    (exactly the preset, nothing changed on top), on the real-KITTI 00 paper tasks."""
    from safl_bench.matching.presets import label

    cells: dict[tuple[str, str, str, str], list[ResultRecord]] = {}
    for r in records:
        name = r.method.name
        if (name in PUBLISHED and r.task.source_kind == SOURCE_KIND and r.task.protocol == "paper"
                and r.task.sequence == SEQUENCE and r.task.condition in CONDITIONS
                and label(r.matcher) == PRESET_OF[name]):
            cells.setdefault((name, r.method.version, weights_text(r), r.task.condition), []).append(r)
    return cells


def _interval(recs: Sequence[ResultRecord]) -> dict[str, Interval | None]:
    ours: dict[str, Interval | None] = {m: None for m, _ in MEASURES}
    if recs:
        sample = intervals.cell_sample(list(recs), "sequence")
        if sample is not None:
            found = sample.intervals()
            ours = {m: found.get(m) for m, _ in MEASURES}
    return ours


def side_by_side(records: Sequence[ResultRecord], selected: Sequence[ResultRecord] = ()) -> list[Row]:
    """Table II's cells beside ours, in the paper's row and column order (module docstring);
    `selected`: records made with checkpoints selected on the test set (rows of their own,
    after the others); [] when no record is under the authors' presets."""
    cells = _selected([*records, *selected])
    rows = []
    for name in PUBLISHED:
        keys = sorted({(v, w) for (n, v, w, _) in cells if n == name},
                      key=lambda vw: (vw[0], "selected on the test set" in vw[1], vw[1]))
        for version, weights in keys:
            for condition in CONDITIONS:
                recs = sorted(cells.get((name, version, weights, condition), []), key=lambda r: r.seed)
                rows.append(Row(name, version, condition, PUBLISHED[name][condition], _interval(recs),
                                tuple(r.seed for r in recs), weights))
    return rows


@dataclass(frozen=True)
class Variant:
    """Records of the Table II tasks with one thing changed (`label` says what), to measure
    what that change does to a cell."""

    name: str
    label: str
    records: list[ResultRecord] = field(default_factory=list)
    about: str = ""

    def cell(self, method: str, version: str, condition: str) -> dict[str, Interval | None] | None:
        """This variant's intervals on one cell; None when it has no records there."""
        recs = sorted((r for r in self.records if r.method.name == method and r.method.version == version
                       and r.task.source_kind == SOURCE_KIND and r.task.sequence == SEQUENCE
                       and r.task.protocol == "paper" and r.task.condition == condition),
                      key=lambda r: r.seed)
        return _interval(recs) if recs else None


VARIANT_FILE = "variant.json"


def load_variants(folder: Path) -> tuple[list[Variant], list[Problem]]:
    """Every `<folder>/<name>/variant.json` ({"label": ..., "about": ...}) with the records
    beside it; a folder without a readable variant.json is a problem, not a variant."""
    variants: list[Variant] = []
    problems: list[Problem] = []
    for sub in sorted(p for p in folder.iterdir() if p.is_dir()) if folder.is_dir() else []:
        path = sub / VARIANT_FILE
        try:
            meta = json.loads(path.read_text(encoding="utf-8"))
            label = str(meta["label"])
        except (OSError, json.JSONDecodeError, KeyError, TypeError) as exc:
            problems.append(Problem(path, f"not a Table II variant ({exc})"))
            continue
        records, bad = load_records(sub)
        problems += bad
        variants.append(Variant(sub.name, label, records, str(meta.get("about", ""))))
    return variants, problems


def _holds(paper: float, iv: Interval | None) -> bool | None:
    if iv is None or iv.low != iv.low:
        return None
    return iv.low * 100 - 0.05 <= paper <= iv.high * 100 + 0.05


def causes(rows: Sequence[Row], variants: Sequence[Variant] = (), measure: str = MEASURES[0][0]) -> list[str]:
    """One line per row whose interval of `measure` misses the paper's value: what each
    measured change gives on that cell (module docstring)."""
    out = []
    for row in rows:
        if row.inside(measure) is not False:
            continue
        iv = row.ours[measure]
        assert iv is not None
        tried = []
        for other in rows:
            if (other is not row and other.method == row.method and other.condition == row.condition
                    and other.ours.get(measure) is not None):
                tried.append((f"{row.method}@{other.version} ({other.weights})", other.ours[measure]))
        for variant in variants:
            found = variant.cell(row.method, row.version, row.condition)
            if found is not None and found.get(measure) is not None:
                tried.append((variant.label, found[measure]))
        head = (f"{PAPER_NAMES[row.method]} @{row.version} ({row.weights}), {row.condition}: paper "
                f"{row.paper:.1f}, ours {iv.format(100.0)}")
        if not tried:
            out.append(f"{head}; no change measured on this cell: unexplained.")
            continue
        found_any = [label for label, v in tried if _holds(row.paper, v)]
        said = "; ".join(f"{label}: {v.format(100.0) if v else 'n/a'}"
                         f"{' (holds it)' if _holds(row.paper, v) else ''}" for label, v in tried)
        verdict = (f"brought onto the paper's value by {' / '.join(found_any)}" if found_any
                   else "no measured change brings it onto the paper's value")
        out.append(f"{head}; {verdict}. Measured: {said}.")
    return out


#: The paper's order, best first.
PAPER_ORDER = ("stable_afl", "bigan", "sad")


@dataclass(frozen=True)
class Order:
    """How often the paper's order holds between two rows of methods (each a method, version and
    weights) over the conditions both have: above beyond the noise, tied, below beyond it."""

    upper: tuple[str, str, str]  # (method, version, weights) the paper puts above
    lower: tuple[str, str, str]
    holds: int
    tied: int
    reversed: int

    def line(self) -> str:
        (mu, vu, wu), (ml, vl, wl) = self.upper, self.lower
        return (f"{PAPER_NAMES[mu]} @{vu} ({wu}) above {PAPER_NAMES[ml]} @{vl} ({wl}), as the paper "
                f"orders them: {self.holds} of {self.holds + self.tied + self.reversed} conditions; "
                f"tied {self.tied}; reversed {self.reversed}.")


def order_counts(rows: Sequence[Row], measure: str = MEASURES[0][0]) -> list[Order]:
    """Per pair of the paper's methods (each method's rows of one version and weights), in how
    many conditions the paper's order holds, is tied (intervals overlap) or is reversed."""
    groups: dict[tuple[str, str, str], dict[str, Interval]] = {}
    for row in rows:
        iv = row.ours.get(measure)
        if iv is not None and iv.low == iv.low:
            groups.setdefault((row.method, row.version, row.weights), {})[row.condition] = iv
    out = []
    for i, upper in enumerate(PAPER_ORDER):
        for lower in PAPER_ORDER[i + 1:]:
            for ku, a in ((k, g) for k, g in groups.items() if k[0] == upper):
                for kl, b in ((k, g) for k, g in groups.items() if k[0] == lower):
                    shared = [c for c in CONDITIONS if c in a and c in b]
                    if not shared:
                        continue
                    holds = sum(a[c].low > b[c].high for c in shared)
                    reversed_ = sum(b[c].low > a[c].high for c in shared)
                    order = Order(ku, kl, holds, len(shared) - holds - reversed_, reversed_)
                    if order not in out:
                        out.append(order)
    return out


def orders(rows: Sequence[Row], measure: str = MEASURES[0][0]) -> list[str]:
    """`order_counts` in words, one line per pair of rows."""
    return [o.line() for o in order_counts(rows, measure)]


def _order_table(rows: Sequence[Row]) -> list[str]:
    """`order_counts` as a Markdown table (README)."""
    def name(key: tuple[str, str, str]) -> str:
        return f"{PAPER_NAMES[key[0]].split(' (')[0]} @{key[1]} ({key[2]})"

    out = ["| The paper's order: above | below | holds | tied | reversed |", "|---|---|---:|---:|---:|"]
    out += [f"| {name(o.upper)} | {name(o.lower)} | {o.holds} | {o.tied} | {o.reversed} |"
            for o in order_counts(rows)]
    return out


TITLE = "Table II side by side: the paper's recall at 100 % precision against ours on real KITTI 00"

INTRO = ("Real KITTI 00 top views (`bev-paper`), the authors' paper-era presets: `authors` "
         "(BiGAN, Stable-AFL) and `authors-sad` (SAD); see `safl-bench list matchers`. "
         "Ours: mean over the seeds [95 % interval over seeds and queries]; *inside*: "
         "whether the paper's value lies in that interval. Two measures: ours (recall at "
         "exactly 100 % precision over every query with a true place) and the authors' "
         "reading (recall over the correctly matched queries at the first precision >= "
         "0.99, `authors_recall_at_99p`). Table II does not say which it reports; the "
         "authors' code reads the second. " + PAPER_NAME_NOTE)


def header() -> list[str]:
    """The column titles, shared by the Markdown table and the site's page."""
    out = ["Method", "Version", "Condition", "Paper", "Seeds", "Weights"]
    for _, title in MEASURES:
        out += [title, "inside"]
    return out


def cells(row: Row) -> list[str]:
    """One row's cells as text ('yes' / 'no' / 'n/a' for inside), in `header()`'s order."""
    out = [PAPER_NAMES[row.method], row.version, row.condition, f"{row.paper:.1f}",
           ",".join(map(str, row.seeds)) or "none", row.weights]
    for measure, _ in MEASURES:
        iv = row.ours.get(measure)
        inside = row.inside(measure)
        out += [iv.format(100.0) if iv is not None else "not run",
                "n/a" if inside is None else ("yes" if inside else "no")]
    return out


def markdown(rows: Sequence[Row], level: int = 1, variants: Sequence[Variant] = ()) -> str:
    """The side-by-side table in Markdown, with how to read it; '' when there are no rows."""
    if not rows:
        return ""
    lines = [f"{'#' * level} {TITLE}", "", INTRO, ""]
    head = header()
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "---|" * len(head))
    for row in rows:
        text = [f"**{c}**" if h == "inside" and c == "no" else c for h, c in zip(head, cells(row), strict=True)]
        lines.append("| " + " | ".join(text) + " |")
    lines.append("")
    lines.extend(f"- {line}" for line in summary(rows))
    order = orders(rows)
    if order:
        lines += ["", f"{'#' * (level + 1)} The paper's order (Stable-AFL > BiGAN > SAD), our measure", ""]
        lines.extend(f"- {line}" for line in order)
    why = causes(rows, variants)
    if why:
        lines += ["", f"{'#' * (level + 1)} What each cell outside its interval gives under the changes measured", ""]
        lines += [f"- **{v.label}** (`{v.name}`): {v.about}" for v in variants if v.about]
        lines += [""] if any(v.about for v in variants) else []
        lines.extend(f"- {line}" for line in why)
    return "\n".join(lines) + "\n"


README_START = "<!-- table2:start -->"
README_END = "<!-- table2:end -->"


def grid(rows: Sequence[Row], measure: str = MEASURES[0][0]) -> str:
    """Table II's own layout: one line per method with the paper's values, then one per version
    and weights of ours (mean [95 % interval], one column per condition); a value of ours
    marked ✗ is one whose interval does not hold the paper's value (a mark, not bold: the README
    that shows this grid uses bold for the best of a column beyond the noise)."""
    head = ["Method", "Version", "Weights", *CONDITIONS]
    lines = ["| " + " | ".join(head) + " |", "|---|---|---|" + "---:|" * len(CONDITIONS)]
    groups: dict[tuple[str, str, str], dict[str, Row]] = {}
    for row in rows:
        groups.setdefault((row.method, row.version, row.weights), {})[row.condition] = row
    for name in PUBLISHED:
        lines.append(f"| {PAPER_NAMES[name]} | paper | | "
                     + " | ".join(f"{PUBLISHED[name][c]:.1f}" for c in CONDITIONS) + " |")
        for (method, version, weights), by_condition in groups.items():
            if method != name:
                continue
            values = []
            for condition in CONDITIONS:
                cell = by_condition.get(condition)
                iv = cell.ours.get(measure) if cell is not None else None
                text = iv.format(100.0) if iv is not None else "—"
                values.append(f"✗ {text}" if cell is not None and cell.inside(measure) is False else text)
            lines.append(f"| {PAPER_NAMES[name]} | {version} | {weights} | " + " | ".join(values) + " |")
    return "\n".join(lines) + "\n"


def readme_block(rows: Sequence[Row], table: str) -> str:
    """The README's Table II block: the grid under our measure, the paper's order per pair, and
    a link to the side-by-side table (`table`: its path inside the leaderboard folder), where
    every cell has both measures and the measured causes."""
    link = f"[{table}](leaderboard/{table})"
    lines = [
        README_START,
        "<!-- written by `safl-bench leaderboard` from the leaderboard's records; do not edit -->",
        "",
        "Table II (the paper's recall at 100 % precision) beside ours on real KITTI 00 top views "
        "under the authors' paper-era presets (`authors`; SAD `authors-sad`), sequence matching: "
        "mean over seeds [95 % interval over seeds and queries], recall over every query with a "
        "true place. ✗: the paper's value lies outside our interval. " + PAPER_NAME_NOTE,
        "",
        grid(rows).rstrip("\n"),
        "",
        *(f"- {line}" for line in summary(rows)),
        "",
        "The paper's order Stable-AFL > BiGAN > SAD, per pair of rows over the twelve conditions "
        "(our measure; overlapping intervals are a tie):",
        "",
        *_order_table(rows),
        "",
        f"Both measures, cell by cell, and what each change measured does to every cell outside "
        f"its interval: {link}.",
        README_END,
    ]
    return "\n".join(lines)


def summary(rows: Sequence[Row]) -> list[str]:
    """How many cells hold the paper's value inside our interval, per measure."""
    out = []
    for measure, title in MEASURES:
        judged = [r for r in rows if r.inside(measure) is not None]
        inside = sum(1 for r in judged if r.inside(measure))
        out.append(f"{title}: the paper's value lies inside our interval in {inside} of "
                   f"{len(judged)} cells.")
    return out


def csv(rows: Sequence[Row]) -> str:
    """The same cells as CSV (fractions as percentages, one line per cell)."""
    header = ["method", "version", "condition", "paper", "seeds", "weights"]
    for measure, _ in MEASURES:
        header += [measure, f"{measure}_low", f"{measure}_high", f"{measure}_paper_inside"]
    lines = [",".join(header)]
    for row in rows:
        cells = [row.method, row.version, row.condition, f"{row.paper:.1f}",
                 " ".join(map(str, row.seeds)), '"' + row.weights.replace('"', "'") + '"']
        for measure, _ in MEASURES:
            iv = row.ours.get(measure)
            if iv is None:
                cells += ["", "", "", ""]
                continue
            inside = row.inside(measure)
            cells += [f"{iv.mean * 100:.1f}", f"{iv.low * 100:.1f}", f"{iv.high * 100:.1f}",
                      "" if inside is None else str(inside).lower()]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"
