"""Regenerate a leaderboard directory from result records.

Layout of the output directory (everything but README.md, records/ and training-logs/ is
generated and overwritten; generated files that a regeneration no longer produces are removed):

    index.md                                  links, headline table, skipped files
    tables/all-results.csv                    every record and matching mode, long format
    tables/<source>/paper-<seq>-v<N>-recall.{md,csv}   Table II (recall at 100 % precision)
    tables/<source>/paper-<seq>-v<N>-auc.{md,csv}      ROC AUC (Figure 13 as numbers)
    tables/<source>/paper-<seq>-v<N>-time.{md,csv}     Table III (ms per frame)
    tables/<source>/revisit-v<N>.{md,csv}              revisit protocol
    figures/<source>/paper-<seq>-v<N>-auc-heatmap.png  Figure 13
    figures/<source>/paper-<seq>-v<N>-pr-<method>-v<version>.png   Figures 10–12
    figures/<source>/revisit-v<N>-pr.png
    figures/training-stability-<source>.png            Figure 14 (from training logs)
    site/                                      the same tables as web pages (leaderboard.site)

The headline is the first table of real data (BEVPlace's top-view images of KITTI, then KITTI
scans) before the synthetic default, the revisit protocol before the paper protocol: what the
field reports today, on the data it reports it on.
"""

from __future__ import annotations

import json
import os
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from safl_bench.common.atomic import atomic_write_text
from safl_bench.errors import DataError
from safl_bench.evaluation.metrics import METRICS_VERSION
from safl_bench.leaderboard import figures as figs
from safl_bench.leaderboard import table2
from safl_bench.leaderboard.grouping import TableKey, group_records, slugify, table_key
from safl_bench.leaderboard.headline import READING, facts_markdown
from safl_bench.leaderboard.report import BuildReport, PublishedTable, headline_rank
from safl_bench.leaderboard.tables import (
    F1_FORMAT,
    Table,
    all_results_frame,
    auc_table,
    bevplace_table,
    frame_csv,
    paper_metric_table,
    preset_table,
    published_bevplace_markdown,
    recall_at_1_table,
    recall_table,
    revisit_table,
    shown_version,
    time_table,
)
from safl_bench.leaderboard.training_logs import TrainingLog, load_training_logs
from safl_bench.results.records import Problem, ResultRecord

GENERATED_DIRS = ("tables", "figures", "site")
#: The synthetic-against-real ranking comparison (`safl_bench.leaderboard.ranking`).
RANKING_MD = "tables/ranking-synthetic-vs-real.md"
RANKING_JSON = "tables/ranking-synthetic-vs-real.json"
RANKING_PNG = "figures/ranking-synthetic-vs-real.png"
GENERATED_SUFFIXES = (".md", ".csv", ".png", ".html", ".json")
UNKNOWN_SOURCE = "data source not recorded in the log"
#: What every table showing a recall says about it (`safl_bench.evaluation.metrics` defines each measure;
#: the text names it by its old path, which still imports, so the committed tables stay byte-identical).
RECALL_NOTE = (
    f"Recall is over the scored queries with a true place (fixed by the ground truth on the "
    f"scored queries, which the note on them names), metrics version {METRICS_VERSION} "
    f"(`safl_bench.metrics`); recall over "
    "correct matches (the paper's authors' and VPR-Bench's convention) is in the `_of_correct` "
    "columns of tables/all-results.csv.")


@dataclass
class _Entry:
    """Links of one table group for the index."""

    key: TableKey
    tables: list[tuple[str, str]] = field(default_factory=list)  # (label, md path)
    figures: list[tuple[str, str]] = field(default_factory=list)  # (label, png path)
    inline: list[str] = field(default_factory=list)  # Markdown shown in the index itself


class _Writer:
    def __init__(self, out: Path, report: BuildReport) -> None:
        self.out = out
        self.report = report

    def text(self, rel: str, content: str) -> str:
        path = self.out / rel
        if not (path.is_file() and path.read_text(encoding="utf-8") == content):
            atomic_write_text(path, content)
        self.report.written.append(path)
        return rel

    def figure(self, rel: str, draw: Callable[[Path], None]) -> str:
        path = self.out / rel
        draw(path)
        self.report.written.append(path)
        return rel


def _version_1_note(group: Sequence[ResultRecord]) -> list[str]:
    """A note naming the rows that come from metrics-version-1 records (kept because version 2
    scores their task the same: `safl_bench.results.records.unchanged_by_version_2`)."""
    old = sorted({f"{r.method.name} v{r.method.version}" for r in group if r.metrics_version == 1})
    if not old:
        return []
    return [f"Rows of {', '.join(old)} come from metrics-version-1 records: version 2 scores this "
            "protocol the same (no ambiguous band, no time window), but they hold no per-query "
            "outcomes, so they have no `_of_correct` measures and no intervals; `safl-bench run "
            "--force` recomputes them."]


def build_leaderboard(
    records: Sequence[ResultRecord],
    out_dir: str | os.PathLike[str],
    *,
    training_logs: str | os.PathLike[str] | None = None,
    skipped: Sequence[Problem] = (),
    skipped_base: str | os.PathLike[str] | None = None,
    figures: bool = True,
    preset_records: Sequence[ResultRecord] = (),
    selected_records: Sequence[ResultRecord] = (),
    table2_variants: Sequence[table2.Variant] = (),
    site: bool = True,
    records_folder: Callable[[ResultRecord], str] | None = None,
    scaling_dir: str | os.PathLike[str] | None = None,
) -> BuildReport:
    """Write the leaderboard for `records` into `out_dir` (see the module docstring).

    `skipped` lists record files the caller could not load; they are named in index.md
    (relative to `skipped_base` when given). `preset_records`: records of the same tasks made
    with other matcher presets (kept in their own folders, since a record's path does not name
    its preset); each paper-protocol table of the top-view images gains a table by preset.
    `site`: also write the web pages (`safl_bench.leaderboard.site`; `records_folder(record)`
    names the folder each record was read from, for their provenance; by default the
    committed layout, leaderboard/records and leaderboard/preset-records/<preset>). `scaling_dir`:
the matcher's scaling runs (default `out_dir`/experiments/matcher-scaling). Raises DataError when
    there are no records, so an empty results directory never wipes a leaderboard.
    """
    if not records:
        raise DataError(
            f"no result records to build the leaderboard in {out_dir} from; "
            "run `safl-bench run` first or pass --results DIR"
        )
    out = Path(out_dir)
    report = BuildReport(out_dir=out, table2_variants=list(table2_variants))
    writer = _Writer(out, report)
    groups, group_notes = group_records(records)
    entries: list[_Entry] = []
    for key, group in groups.items():
        notes = [RECALL_NOTE, *_version_1_note(group), *group_notes.get(key, [])]
        base = f"{key.source_slug}/{key.stem}"
        entry = _Entry(key)
        if key.protocol == "paper":
            recall = recall_table(key, group, notes)
            auc = auc_table(key, group, notes)
            timing = time_table(key, group, notes[1:])
            heatmap = f"figures/{base}-auc-heatmap.png"
            f1 = paper_metric_table(key, group, metric="f1_max", title="F1max", fmt=F1_FORMAT,
                                    notes=notes)
            r1 = recall_at_1_table(key, group, notes)
            for label, table, stem, rebuild in (
                ("Recall at 100 % precision (Table II)", recall, "recall", partial(recall_table, key)),
                ("F1max", f1, "f1max", partial(paper_metric_table, key, metric="f1_max",
                                               title="F1max", fmt=F1_FORMAT)),
                ("Recall@1", r1, "recall-at-1", partial(recall_at_1_table, key)),
                ("ROC AUC (Figure 13)", auc, "auc", partial(auc_table, key)),
                ("ms per frame (Table III)", timing, "time", partial(time_table, key)),
            ):
                md = table.markdown(level=1)
                rel = writer.text(f"tables/{base}-{stem}.md", md)
                entry.tables.append((label, rel))
                report.tables.append(PublishedTable(key, label, rel, table, group, rebuild))
                writer.text(f"tables/{base}-{stem}.csv", table.csv())
            _offer_headline(report, recall, [f1, r1, auc], group)
            presets = [r for r in preset_records if table_key(r) == key]
            if key.source_kind == "bev" and presets:
                for metric, stem, title in (
                    ("recall_at_100_precision", "presets-recall", "recall at 100 % precision (%)"),
                    ("recall_at_1", "presets-recall-at-1", "Recall@1 (%)"),
                ):
                    by_preset = preset_table(key, [*group, *presets], metric=metric,
                                             title=f"Sequence matcher by preset: {title}",
                                             notes=[RECALL_NOTE])
                    md = by_preset.markdown(level=1)
                    rel = writer.text(f"tables/{base}-{stem}.md", md)
                    entry.tables.append((f"by matcher preset, {title}", rel))
                    report.tables.append(PublishedTable(
                        key, f"by matcher preset, {title}", rel, by_preset, [*group, *presets],
                        partial(preset_table, key, metric=metric,
                                title=f"Sequence matcher by preset: {title}")))
                    writer.text(f"tables/{base}-{stem}.csv", by_preset.csv())
                    entry.inline.append(by_preset.markdown(level=4))
                side = table2.side_by_side([*group, *presets], selected_records)
                if side:
                    rel = writer.text(f"tables/{base}-table2-side-by-side.md",
                                      table2.markdown(side, level=1, variants=table2_variants))
                    writer.text(f"tables/{base}-table2-side-by-side.csv", table2.csv(side))
                    entry.tables.append(("Table II side by side", rel))
                    report.table2[key] = (side, rel)
                    report.table2_notes[key] = (table2.orders(side), table2.causes(side, table2_variants))
                    entry.inline.append(table2.markdown(side, level=4, variants=table2_variants))
            if figures:
                entry.figures.append(
                    ("AUC heat map", writer.figure(heatmap, partial(figs.auc_heatmap, auc)))
                )
                by_method: dict[tuple[str, str], list[ResultRecord]] = defaultdict(list)
                for record in group:
                    by_method[(record.method.name, shown_version(record))].append(record)
                for (name, version), recs in sorted(by_method.items()):
                    rel = f"figures/{base}-pr-{slugify(name)}-v{slugify(version)}.png"
                    entry.figures.append(
                        (
                            f"PR curves {name} v{version}",
                            writer.figure(rel, partial(figs.pr_figure, key, name, version, recs)),
                        )
                    )
        else:
            bevplace = key.protocol == "bevplace"
            table = (bevplace_table if bevplace else revisit_table)(key, group, notes)
            md = table.markdown(level=1) + ("\n" + published_bevplace_markdown(2) if bevplace else "")
            label = "Recall@1/5/10, F1max" if bevplace else "F1max, recall at 100 % precision, AUC, Recall@1"
            rel = writer.text(f"tables/{base}.md", md)
            entry.tables.append((label, rel))
            report.tables.append(PublishedTable(
                key, label, rel, table, group, partial(bevplace_table if bevplace else revisit_table, key)))
            if not bevplace:
                _offer_headline(report, table, [], group)
            if key.source_kind == "bev":  # real KITTI: its tables stand in the index itself
                entry.inline = [table.markdown(level=4)] + ([published_bevplace_markdown(4)] if bevplace else [])
            writer.text(f"tables/{base}.csv", table.csv())
            if not bevplace:  # loop closure in SLAM, from the result files beside the records
                from safl_bench.leaderboard import slam_table

                slam_folder = Path(records_folder(group[0])) if records_folder else out / "records"
                slam_cells = slam_table.load_cells(group, slam_folder)
                slam_md = slam_table.slam_markdown(key.caption, slam_cells)
                if slam_md is not None:
                    rel = writer.text(f"tables/{base}-slam.md", slam_md)
                    writer.text(f"tables/{base}-slam.json", slam_table.slam_json(slam_cells))
                    entry.tables.append(("Loop closure in SLAM: ATE per back-end", rel))
                    if figures:
                        from safl_bench.leaderboard import slam_figures

                        entry.figures.append(("SLAM: ATE per method and back-end", writer.figure(
                            f"figures/{base}-slam-ate.png", partial(slam_figures.ate_bars, slam_cells))))
            if figures:
                rel = f"figures/{base}-pr.png"
                entry.figures.append(
                    ("PR curves", writer.figure(rel, partial(figs.revisit_pr_figure, key, group)))
                )
        entries.append(entry)
        report.figure_links[key] = entry.figures

    writer.text("tables/all-results.csv", frame_csv(all_results_frame(records)))

    from safl_bench.leaderboard import ranking

    comps = ranking.comparisons(records)
    ranking_md = ""
    if comps:
        ranking_md = ranking.markdown(comps, level=2)
        report.ranking = comps
        report.ranking_md = writer.text(RANKING_MD, ranking.markdown(comps, level=1))
        writer.text(RANKING_JSON, json.dumps([c.to_json() for c in comps], indent=1,
                                             sort_keys=True) + "\n")
        if figures:
            report.ranking_figure = writer.figure(RANKING_PNG, partial(ranking.figure, comps))

    from safl_bench.leaderboard import scaling

    runs, scaling_problems = scaling.load(Path(scaling_dir) if scaling_dir is not None
                                          else out / scaling.FOLDER)
    report.problems.extend(scaling_problems)
    if runs:
        report.scaling = runs
        writer.text(scaling.MD, scaling.markdown(runs))
        if figures:
            report.scaling_figure = writer.figure(scaling.PNG, partial(scaling.figure, runs))

    training: list[tuple[str, str, list[str]]] = []
    if training_logs is not None:
        logs, log_problems = load_training_logs(training_logs)
        report.problems.extend(log_problems)
        if figures:
            by_source: dict[str, list[TrainingLog]] = defaultdict(list)
            for log in logs:
                by_source[log.source or UNKNOWN_SOURCE].append(log)
            for source, source_logs in sorted(by_source.items()):
                rel = f"figures/training-stability-{slugify(source)}.png"
                writer.figure(rel, partial(figs.training_figure, source_logs, source))
                training.append((source, rel, [log.method for log in source_logs]))

    report.training_figures = training
    report.problems.extend(skipped)
    index = _index(records, entries, report.headline, training, skipped, skipped_base, figures,
                   report.headline_robust, report.headline_records, ranking_md,
                   report.ranking_figure)
    writer.text("index.md", index)
    if site:
        from safl_bench.leaderboard.site import default_records_folder, write_site

        folder = records_folder or default_records_folder(preset_records)
        report.written += write_site(report, records_folder=folder, problems=skipped,
                                     problem_base=skipped_base)
    report.removed = _remove_stale(out, report.written)
    return report


def _offer_headline(report: BuildReport, table: Table, robust: list[Table],
                    records: list[ResultRecord]) -> None:
    """Make `table` the headline if it ranks before the current one."""
    if report.headline is None or headline_rank(table.key) < headline_rank(report.headline.key):
        report.headline = table
        report.headline_robust = robust
        report.headline_records = records


def _index(
    records: Sequence[ResultRecord],
    entries: list[_Entry],
    headline: Table | None,
    training: list[tuple[str, str, list[str]]],
    skipped: Sequence[Problem],
    skipped_base: str | os.PathLike[str] | None,
    figures: bool,
    robust: Sequence[Table] = (),
    headline_records: Sequence[ResultRecord] = (),
    ranking_md: str = "",
    ranking_figure: str | None = None,
) -> str:
    lines = [
        "# safl-bench leaderboard",
        "",
        f"Regenerated by `safl-bench leaderboard` from {len(records)} result records; do not edit "
        "by hand. [README.md](README.md) says how to add a method's results and how cells are "
        "combined.",
        "",
        "Matching: *sequence* = the shared SeqSLAM sequence matcher (paper §II.D); *single-frame* = "
        "the best single database frame for each query. Missing cells show —.",
        "",
    ]
    if headline is not None:
        lines += ["## Headline", "", facts_markdown(headline, headline_records), "",
                  READING, "", headline.markdown(level=3), ""]
        for table in robust:
            lines += [table.markdown(level=3), ""]
    current_source = None
    for entry in entries:
        key = entry.key
        if key.source_label != current_source:
            current_source = key.source_label
            lines += [f"## {key.source_label}", ""]
        what = (
            f"Paper protocol, sequence {key.sequence}"
            if key.protocol == "paper"
            else "BEVPlace's protocol" if key.protocol == "bevplace"
            else f"{key.protocol.capitalize()} protocol"
        )
        lines += [f"### {what}, task version v{key.task_version}", ""]
        lines.append(
            "- Tables: "
            + " · ".join(f"[{label}]({md}) ([CSV]({md[:-3]}.csv))" for label, md in entry.tables)
        )
        if entry.figures:
            lines.append(
                "- Figures: " + " · ".join(f"[{label}]({png})" for label, png in entry.figures)
            )
        lines.append("")
        for block in entry.inline:
            lines += [block.rstrip("\n"), ""]
    if figures:
        lines += ["## Training stability (Figure 14)", ""]
        if training:
            lines += [
                f"- [{source}]({rel}): {', '.join(methods)}" for source, rel, methods in training
            ]
        else:
            lines.append("- No training logs were found.")
        lines.append("")
    if ranking_md:
        lines += [ranking_md.rstrip("\n"), ""]
        if ranking_figure:
            lines += [f"- Figure: [synthetic against real, Recall@1 per method]({ranking_figure}) "
                      f"· [JSON]({RANKING_JSON})", ""]
    lines += [
        "## All results",
        "",
        "- [tables/all-results.csv](tables/all-results.csv): one row per record and matching mode, "
        "with every metric, timing and the git revision.",
        "",
    ]
    if skipped:
        lines += ["## Skipped record files", ""]
        for problem in skipped:
            lines.append(f"- `{_relative(problem.path, skipped_base)}`: {problem.reason}")
        lines.append("")
    return "\n".join(lines).rstrip("\n") + "\n"


def _relative(path: Path, base: str | os.PathLike[str] | None) -> str:
    if base is None:
        return str(path)
    try:
        return str(Path(path).relative_to(base))
    except ValueError:
        return str(path)


def _remove_stale(out: Path, written: list[Path]) -> list[Path]:
    keep = {p.resolve() for p in written}
    removed: list[Path] = []
    for sub in GENERATED_DIRS:
        root = out / sub
        if not root.is_dir():
            continue
        for path in sorted(root.rglob("*")):
            if path.is_file() and path.suffix in GENERATED_SUFFIXES and path.resolve() not in keep:
                path.unlink()
                removed.append(path)
        for directory in sorted((d for d in root.rglob("*") if d.is_dir()), reverse=True):
            if not any(directory.iterdir()):
                directory.rmdir()
    return removed
