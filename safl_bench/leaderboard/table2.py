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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from safl_bench.evaluation.uncertainty import Interval
from safl_bench.leaderboard import intervals
from safl_bench.results.records import ResultRecord

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

    def inside(self, measure: str) -> bool | None:
        """Whether the paper's value lies in our interval of `measure` (None: no interval)."""
        iv = self.ours.get(measure)
        if iv is None or iv.low != iv.low:
            return None
        return iv.low * 100 - 0.05 <= self.paper <= iv.high * 100 + 0.05


def _selected(records: Sequence[ResultRecord]) -> dict[tuple[str, str, str], list[ResultRecord]]:
    """The records of each (method, version, condition) under that method's preset (exactly
    the preset, nothing changed on top), on the real-KITTI 00 paper tasks."""
    from safl_bench.matching.presets import label

    cells: dict[tuple[str, str, str], list[ResultRecord]] = {}
    for r in records:
        name = r.method.name
        if (name in PUBLISHED and r.task.source_kind == SOURCE_KIND and r.task.protocol == "paper"
                and r.task.sequence == SEQUENCE and r.task.condition in CONDITIONS
                and label(r.matcher) == PRESET_OF[name]):
            cells.setdefault((name, r.method.version, r.task.condition), []).append(r)
    return cells


def side_by_side(records: Sequence[ResultRecord]) -> list[Row]:
    """Table II's cells beside ours, in the paper's row and column order (module docstring);
    [] when no record is under the authors' presets."""
    cells = _selected(records)
    rows = []
    for name in PUBLISHED:
        versions = sorted({v for (n, v, _) in cells if n == name})
        for version in versions:
            for condition in CONDITIONS:
                recs = sorted(cells.get((name, version, condition), []), key=lambda r: r.seed)
                ours: dict[str, Interval | None] = {m: None for m, _ in MEASURES}
                if recs:
                    sample = intervals.cell_sample(recs, "sequence")
                    if sample is not None:
                        found = sample.intervals()
                        ours = {m: found.get(m) for m, _ in MEASURES}
                rows.append(Row(name, version, condition, PUBLISHED[name][condition], ours,
                                tuple(r.seed for r in recs)))
    return rows


TITLE = "Table II side by side: the paper's recall at 100 % precision against ours on real KITTI 00"

INTRO = ("Real KITTI 00 top views (`bev-paper`), the authors' paper-era presets: `authors` "
         "(BiGAN, Stable-AFL) and `authors-sad` (SAD); see `safl-bench list matchers`. "
         "Ours: mean over the seeds [95 % interval over seeds and queries]; *inside*: "
         "whether the paper's value lies in that interval. Two measures: ours (recall at "
         "exactly 100 % precision over every query with a true place) and the authors' "
         "reading (recall over the correctly matched queries at the first precision >= "
         "0.99, `authors_recall_at_99p`). Table II does not say which it reports; the "
         "authors' code reads the second.")


def header() -> list[str]:
    """The column titles, shared by the Markdown table and the site's page."""
    out = ["Method", "Version", "Condition", "Paper", "Seeds"]
    for _, title in MEASURES:
        out += [title, "inside"]
    return out


def cells(row: Row) -> list[str]:
    """One row's cells as text ('yes' / 'no' / 'n/a' for inside), in `header()`'s order."""
    out = [PAPER_NAMES[row.method], row.version, row.condition, f"{row.paper:.1f}",
           ",".join(map(str, row.seeds)) or "none"]
    for measure, _ in MEASURES:
        iv = row.ours.get(measure)
        inside = row.inside(measure)
        out += [iv.format(100.0) if iv is not None else "not run",
                "n/a" if inside is None else ("yes" if inside else "no")]
    return out


def markdown(rows: Sequence[Row], level: int = 1) -> str:
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
    return "\n".join(lines) + "\n"


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
    header = ["method", "version", "condition", "paper", "seeds"]
    for measure, _ in MEASURES:
        header += [measure, f"{measure}_low", f"{measure}_high", f"{measure}_paper_inside"]
    lines = [",".join(header)]
    for row in rows:
        cells = [row.method, row.version, row.condition, f"{row.paper:.1f}",
                 " ".join(map(str, row.seeds))]
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
