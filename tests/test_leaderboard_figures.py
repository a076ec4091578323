"""Leaderboard figures show the spread: the heat map's cells carry the tables' intervals, the PR
figures draw every seed's curve."""

from __future__ import annotations

from pathlib import Path

import pytest
from matplotlib.figure import Figure
from record_factory import make_record, scored_record

from safl_bench.leaderboard import figures
from safl_bench.leaderboard.grouping import Cell, TableKey, group_records
from safl_bench.leaderboard.tables import auc_table, recall_at_1_table


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch) -> list[Figure]:
    """The figures the module saves, kept instead of written."""
    kept: list[Figure] = []
    monkeypatch.setattr(figures, "save_png", lambda fig, path: kept.append(fig))
    return kept


def _key(records: list) -> TableKey:
    groups, _ = group_records(records)
    (key,) = groups
    return key


def test_heatmap_text_is_mean_over_interval() -> None:
    assert figures.heatmap_text(Cell(mean=0.912, low=0.881, high=0.944)) == "0.91\n[0.88, 0.94]"
    assert figures.heatmap_text(Cell(mean=0.9)) == "0.90"  # no interval: the mean alone
    assert figures.heatmap_text(None) == figures.heatmap_text(Cell(mean=None)) == "—"


def test_heatmap_cells_show_the_tables_intervals(drawn: list[Figure], tmp_path: Path) -> None:
    records = [scored_record(m, seed=s, skill=k, variant=v, condition="T1R1")
               for m, k, v in (("strong", 0.95, 0), ("weak", 0.3, 1)) for s in range(3)]
    key = _key(records)
    # the AUC table in the leaderboard; Recall@1 here, whose order these draws resolve (bold)
    for table in (auc_table(key, records), recall_at_1_table(key, records)):
        figures.auc_heatmap(table, tmp_path / "h.png")
    table = recall_at_1_table(key, records)
    fig = drawn[-1]
    shown = {t.get_text(): t for ax in fig.axes for t in ax.texts}
    for i, _ in enumerate(table.rows):
        cell = table.cells[i][0]
        assert cell is not None and cell.low is not None and cell.low < cell.mean < cell.high
        text = f"{cell.mean:.2f}\n[{cell.low:.2f}, {cell.high:.2f}]"
        assert text in shown
        weight = "bold" if table.marks.get((i, 0)) == "best" else "normal"
        assert shown[text].get_fontweight() == weight
    assert "best" in table.marks.values()  # the strong method is better beyond the noise


def test_pr_figure_draws_one_curve_per_seed(drawn: list[Figure], tmp_path: Path) -> None:
    records = [make_record("stable_afl", condition=c, seed=s, auc=0.8 + 0.03 * s)
               for c in ("T1R1", "T5R1") for s in range(3)]
    figures.pr_figure(_key(records), "stable_afl", "1", records, tmp_path / "pr.png")
    (fig,) = drawn
    panels = [ax for ax in fig.axes if ax.get_xlabel() == "recall"]
    assert len(panels) == 2  # sequence and single-frame
    for ax in panels:
        assert len(ax.lines) == 6  # 2 conditions x 3 seeds
        assert all(line.get_alpha() == 0.6 and line.get_linewidth() == 0.7 for line in ax.lines)
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert labels == ["T1R1", "T5R1"]  # one legend entry per condition, not per seed
    assert "one curve per seed: seeds 0, 1, 2" in fig.texts[0].get_text()


def test_pr_figure_of_one_seed_is_drawn_as_before(drawn: list[Figure], tmp_path: Path) -> None:
    records = [make_record("stable_afl", condition="T1R1")]
    figures.pr_figure(_key(records), "stable_afl", "1", records, tmp_path / "pr.png")
    (fig,) = drawn
    line = fig.axes[0].lines[0]
    assert line.get_linewidth() == 1.2 and line.get_alpha() is None
    assert "per seed" not in fig.texts[0].get_text()


def test_revisit_pr_figure_draws_every_seed(drawn: list[Figure], tmp_path: Path) -> None:
    records = [make_record(m, protocol="revisit", condition=None, seed=s)
               for m in ("sad", "stable_afl") for s in range(2)]
    figures.revisit_pr_figure(_key(records), records, tmp_path / "rv.png")
    (fig,) = drawn
    ax = fig.axes[0]
    assert len(ax.lines) == 4 and [t.get_text() for t in ax.get_legend().get_texts()] == [
        "sad v1", "stable_afl v1"]
