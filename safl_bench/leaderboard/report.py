"""What a regeneration of the leaderboard wrote (`BuildReport`, `PublishedTable`) and which of
its tables is the headline (`headline_rank`): read by the index (`build`) and by the web pages
(`site`), which `build` writes, so they live apart from both.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from safl_bench.leaderboard.grouping import TableKey
from safl_bench.leaderboard.ranking import Comparison
from safl_bench.leaderboard.table2 import Row, Variant
from safl_bench.leaderboard.tables import Table
from safl_bench.results.records import Problem, ResultRecord


@dataclass
class PublishedTable:
    """One table as the leaderboard wrote it, with what the web pages need to explain its cells.

    `rebuild` is the function that made `table` from `records`: the site calls it on one record
    at a time to learn which record (seed) gives which cell, so it never re-derives a column.
    """

    key: TableKey
    label: str
    md: str  # the Markdown file, relative to the leaderboard directory
    table: Table
    records: list[ResultRecord]
    rebuild: Callable[[list[ResultRecord]], Table]


@dataclass
class BuildReport:
    """What a regeneration wrote, removed and could not use."""

    out_dir: Path
    written: list[Path] = field(default_factory=list)
    removed: list[Path] = field(default_factory=list)
    problems: list[Problem] = field(default_factory=list)
    headline: Table | None = None
    #: the headline condition's measures that do not collapse on one false positive
    headline_robust: list[Table] = field(default_factory=list)
    #: the headline's records (its source, protocol, matcher presets and seeds are read from them)
    headline_records: list[ResultRecord] = field(default_factory=list)
    #: every table written, in the index's order, and the figures of each table group
    tables: list[PublishedTable] = field(default_factory=list)
    figure_links: dict[TableKey, list[tuple[str, str]]] = field(default_factory=dict)
    training_figures: list[tuple[str, str, list[str]]] = field(default_factory=list)
    #: Table II beside ours (`table2.side_by_side`), per table group that has it, with its Markdown
    table2: dict[TableKey, tuple[list[Row], str]] = field(default_factory=dict)
    #: per table group with Table II: the lines on the paper's order and on each cell outside
    #: its interval (`table2.orders`, `table2.causes`)
    table2_notes: dict[TableKey, tuple[list[str], list[str]]] = field(default_factory=dict)
    #: the Table II variants the build read (`table2.load_variants`): what each measured change gives
    table2_variants: list[Variant] = field(default_factory=list)
    #: the synthetic-against-real ranking comparisons (`ranking.comparisons`), their Markdown
    #: table and figure (relative to the leaderboard directory; None: not drawn)
    ranking: list[Comparison] = field(default_factory=list)
    ranking_md: str | None = None
    ranking_figure: str | None = None
    #: the matcher's scaling runs (`scaling.load`: experiments/matcher-scaling/*.json), and
    #: the figure drawn of them (None: not drawn)
    scaling: list[dict[str, Any]] = field(default_factory=list)
    scaling_figure: str | None = None


def headline_rank(key: TableKey) -> tuple[object, ...]:
    """Headline = real data first (top-view images of KITTI, then KITTI scans, then the synthetic
    default), the revisit protocol before the paper's, lowest sequence, newest version."""
    kinds = ("bev", "kitti", "synth")
    kind = kinds.index(key.source_kind) if key.source_kind in kinds else len(kinds)
    return (kind, key.protocol != "revisit", key.source_label, key.sequence, -key.task_version)
