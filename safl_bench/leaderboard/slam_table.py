"""The "loop closure in SLAM" table of a revisit table's source: from the loop-closure result files
(`safl_bench.slam.cell`) beside the records, never recomputed here, so the build stays fast.

Rows are (method, matching mode); for each task of the source, columns ATE RMSE of least squares,
Cauchy and GNC-TLS at the *deployed* operating point (the threshold chosen on the partner sequence,
`safl_bench.slam.cell.DEPLOY_FROM`), mean over the SLAM seeds with its 95 % interval
(`slam.cell.seed_interval`), and the closures accepted (true/false, the same on every seed: the
threshold and matches do not depend on it). Only results of the default settings (mid drift,
RPE over 100 m) count, and a cell counts when it has every one of `DEFAULT_SLAM_SEEDS` seeds.
Ranks as the other tables mark them: bold the lowest mean of a column beyond the noise (its paired
difference over the same seeds, `slam.cell.paired_ate_difference`, to every other row excludes 0),
≈ every row tied with it; a row with no closure (the odometry alone) is never ranked. The odometry alone (the same for every method of a task) is its own
row. Compute the result files with `safl-bench slam --deployed` (docs/guides/slam.md).
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from safl_bench.leaderboard.intervals import BEST, TIED
from safl_bench.methods.training_data import record_seen, seen_mark
from safl_bench.results.records import ResultRecord, is_repeat
from safl_bench.slam.backend import BACKENDS
from safl_bench.slam.cell import (
    DEFAULT_RPE_DELTA_M,
    DEFAULT_SLAM_SEEDS,
    SlamResult,
    band_closures,
    paired_ate_difference,
    read_result,
    seed_interval,
)
from safl_bench.slam.model import DEFAULT_DRIFT

MODE_LABEL = {"sequence": "sequence", "single_frame": "single-frame"}


@dataclass(frozen=True)
class SlamCell:
    """One (method, task, mode) over its SLAM seeds."""

    method: str
    task: str
    mode: str
    results: tuple[SlamResult, ...]  # ordered by SLAM seed
    #: the record's training mark (`training_data.seen_mark`: weights trained on this task's
    #: frames); such rows are shown, never ranked, as in the revisit table
    seen: str = ""
    #: of its false closures, those in the protocol's 3-20 m band (`slam.cell.band_closures`;
    #: None: the record holds no per-query matches)
    band: int | None = None

    def ate(self, backend: str | None) -> list[float]:
        return [r.ate(backend) for r in self.results]


def load_cells(records: Sequence[ResultRecord], folder: Path) -> list[SlamCell]:
    """The deployed, default-settings loop-closure cells of `records` found under `folder` (the
    records' folder: ``<method>@<version>/<task>/slam-seed-<n>.s<k>.<digest>.json``)."""
    cells = []
    for record in records:
        if is_repeat(record):  # a repeated run of an unseedable method: its first run is scored
            continue
        directory = folder / f"{record.method.name}@{record.method.version}" / record.task.id.replace("/", "__")
        found: dict[str, dict[int, SlamResult]] = defaultdict(dict)
        for path in sorted(directory.glob(f"slam-seed-{record.seed}.s*.json")):
            result = read_result(path)
            if (result is None or result.slam_seed is None
                    or not result.threshold_rule.startswith("deployed")
                    or result.settings.get("drift") != DEFAULT_DRIFT
                    or result.settings.get("rpe_delta_m") != DEFAULT_RPE_DELTA_M
                    or result.record_created != record.created):
                continue
            found[result.settings["mode"]][result.slam_seed] = result
        for mode, by_seed in sorted(found.items()):
            if set(range(DEFAULT_SLAM_SEEDS)) <= set(by_seed):
                results = tuple(by_seed[s] for s in range(DEFAULT_SLAM_SEEDS))
                cells.append(SlamCell(f"{record.method.name}@{record.method.version}", record.task.id,
                                      mode, results, seen_mark(record_seen(record)),
                                      band_closures(record, mode, results[0].threshold)))
    return cells


def _marks(cells: Sequence[SlamCell], backend: str) -> dict[int, str]:
    """{index: BEST or TIED} for the lowest ATE of one column (module doc)."""
    means = [float(sum(c.ate(backend)) / len(c.results)) for c in cells]
    finite = [i for i, m in enumerate(means) if math.isfinite(m)]
    if len(finite) < 2 or len({round(means[i], 2) for i in finite}) == 1:
        return {}
    top, *rest = sorted(finite, key=lambda i: (means[i], i))
    tied = [i for i in rest if not (lambda d: d.excludes_zero() and d.mean < 0)(
        paired_ate_difference(cells[top].ate(backend), cells[i].ate(backend)))]
    return {top: BEST} if not tied else {i: TIED for i in (top, *tied)}


def _band(cell: SlamCell) -> str:
    """The false closures of a row that lie in the 3-20 m band, when it has false closures."""
    if cell.band is None or not cell.results[0].closures_false:
        return ""
    return f" ({cell.band} in 3–20 m)"


def _text(values: list[float], mark: str | None) -> str:
    text = seed_interval(values).format(decimals=2)
    if mark == BEST:
        return f"**{text}**"
    return f"≈ {text}" if mark == TIED else text


def slam_markdown(title: str, cells: Sequence[SlamCell], level: int = 1) -> str | None:
    """The table (module doc) of `cells`, one block per task; None when there are none."""
    if not cells:
        return None
    by_task: dict[str, list[SlamCell]] = defaultdict(list)
    for cell in cells:
        by_task[cell.task].append(cell)
    hashes = "#" * level
    lines = [f"{hashes} Loop closure in SLAM: ATE RMSE (m) at the deployed threshold — {title}", "",
             f"Each method's accepted loop closures through a 2-D pose graph (`safl-bench slam`, "
             f"docs/guides/slam.md): ground-truth motion with {DEFAULT_DRIFT} odometry drift, true "
             "closures with registration noise, false ones random; least squares, a Cauchy kernel "
             f"and GNC with truncated least squares. Mean over SLAM seeds 0–{DEFAULT_SLAM_SEEDS - 1} "
             "(the drift and closure-noise draws, shared by every method of a seed) [95 % interval "
             "over the seeds]. Threshold: the lowest keeping 100 % precision on the partner "
             "sequence named, deployed here (never chosen on the sequence scored). **Bold**: lowest "
             "of its column and matching mode beyond the noise (paired over seeds); ≈: tied for lowest. A "
             "row marked as seen in training (its weights were trained on frames of this task, "
             "the revisit table's mark) is shown, never ranked, and so is a row that accepted no "
             "closure (it is the odometry alone). *false* counts every accepted closure whose "
             "match is not a true place, those 3–20 m away included, which the recall tables "
             "leave out as ambiguous; the count in brackets is how many of a row's false "
             "closures lie in that band. Each false closure enters the graph as a random "
             "measurement.", ""]
    for task, group in sorted(by_task.items()):
        group.sort(key=lambda c: (c.mode != "sequence", c.method))
        first = group[0].results[0]
        source = first.threshold_rule.split(" on ", 1)[-1].split(" seed ")[0]
        lines += [f"{hashes}# {task} ({first.n_poses} poses; thresholds from {source})", "",
                  "| Method | Matching | closures true / false | " + " | ".join(
                      f"ATE {b} (m)" for b in BACKENDS) + " |",
                  "|---|---|---:|" + "---:|" * len(BACKENDS)]
        marks: dict[str, dict[int, str]] = {b: {} for b in BACKENDS}
        for mode in {c.mode for c in group}:  # ranked within a matching mode, as the revisit table
            # a row that accepted no closure is the odometry alone: shown, never ranked
            index = [i for i, c in enumerate(group) if c.mode == mode and not c.seen
                     and c.results[0].closures_true + c.results[0].closures_false > 0]
            for b in BACKENDS:
                marks[b].update({index[k]: m for k, m in _marks([group[i] for i in index], b).items()})
        odometry = group[0].ate(None)
        lines.append("| odometry alone | — | 0 / 0 | "
                     + " | ".join(seed_interval(odometry).format(decimals=2) for _ in BACKENDS) + " |")
        for i, cell in enumerate(group):
            r = cell.results[0]
            estimated = f" ({r.closures_estimated} own pose)" if r.closures_estimated else ""
            failed = [b for b in BACKENDS if any(v != v for v in cell.ate(b))]
            lines.append(f"| {cell.method}{cell.seen} | {MODE_LABEL.get(cell.mode, cell.mode)} | "
                         f"{r.closures_true} / {r.closures_false}{_band(cell)}{estimated} | "
                         + " | ".join(_text(cell.ate(b), marks[b].get(i)) for b in BACKENDS) + " |"
                         + (f" (did not converge on some seed: {', '.join(failed)})" if failed else ""))
        lines.append("")
    return "\n".join(lines)


def slam_json(cells: Sequence[SlamCell]) -> str:
    """The table's numbers as JSON (one entry per cell: per back-end mean, low, high)."""
    rows = []
    for cell in cells:
        row = {"method": cell.method, "task": cell.task, "mode": cell.mode,
               "closures_true": cell.results[0].closures_true,
               "closures_false": cell.results[0].closures_false,
               "closures_false_in_band": cell.band,
               "threshold": cell.results[0].threshold,
               "threshold_rule": cell.results[0].threshold_rule}
        for b in (None, *BACKENDS):
            interval = seed_interval(cell.ate(b))
            row[f"ate_{b or 'odometry'}"] = [interval.mean, interval.low, interval.high]
        rows.append(row)
    return json.dumps(rows, indent=2, allow_nan=True) + "\n"


def slam_html(markdown: str) -> str:
    """The table's Markdown (`slam_markdown`) as HTML for the web page: headings, paragraphs and
    pipe tables (the only constructs it writes); bold and ≈ marks kept."""
    import html
    import re

    def inline(text: str) -> str:
        escaped = html.escape(text, quote=True)
        escaped = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", escaped)
        parts = escaped.split("`")
        return "".join(f"<code>{p}</code>" if k % 2 else p for k, p in enumerate(parts))

    out: list[str] = []
    rows: list[list[str]] = []

    def flush() -> None:
        if rows:
            head, *body = rows
            out.append("<table><thead><tr>" + "".join(f"<th>{inline(c)}</th>" for c in head)
                       + "</tr></thead><tbody>" + "".join(
                           "<tr>" + "".join(f"<td>{inline(c)}</td>" for c in r) + "</tr>" for r in body)
                       + "</tbody></table>")
            rows.clear()

    for line in markdown.splitlines():
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if not all(set(c) <= set("-:") for c in cells):
                rows.append(cells)
            continue
        flush()
        if line.startswith("#"):
            level = min(len(line) - len(line.lstrip("#")) + 1, 4)
            out.append(f"<h{level}>{inline(line.lstrip('#').strip())}</h{level}>")
        elif line.strip():
            out.append(f"<p>{inline(line)}</p>")
    flush()
    return "".join(out)
