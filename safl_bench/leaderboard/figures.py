"""Leaderboard figures: PR curves per method (paper Figs. 10–12), the AUC heat map (Fig. 13),
training stability (Fig. 14) and revisit-protocol PR curves.

Figures are drawn with matplotlib's object API on the Agg canvas (no pyplot, no global backend
switch) under matplotlib's default style, at fixed sizes and dpi, and saved without the
"Software" metadata, so the same records give byte-identical PNGs on the same library versions.
Every title names the data source.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import matplotlib
import matplotlib.style
import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from safl_bench.common.atomic import atomic_write_with
from safl_bench.errors import ConfigError
from safl_bench.leaderboard.grouping import Cell, TableKey, condition_order, format_seeds
from safl_bench.leaderboard.intervals import BEST
from safl_bench.leaderboard.tables import MISSING, MODE_LABELS, Table, shown_version
from safl_bench.leaderboard.training_logs import TrainingLog
from safl_bench.results.records import MODES, ResultRecord
from safl_bench.views.noise import Condition

DPI = 100
_TRANSLATION_COLORS = {1.0: "tab:blue", 5.0: "tab:orange", 10.0: "tab:green", 20.0: "tab:red"}
_HEADING_STYLES = {1.0: "-", 1.5: "--", 2.0: ":"}
_FALLBACK_COLORS = ("tab:purple", "tab:brown", "tab:pink", "tab:gray", "tab:olive", "tab:cyan")


def _new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_png(fig: Figure, path: Path) -> None:
    """Write `fig` to `path` atomically as a reproducible PNG."""
    atomic_write_with(
        path, lambda tmp: fig.savefig(tmp, format="png", dpi=DPI, metadata={"Software": None})
    )


def _condition_style(name: str, index: int) -> dict[str, str]:
    try:
        cond: Condition | None = Condition.parse(name)
    except ConfigError:
        cond = None
    if cond is not None and cond.translation_m in _TRANSLATION_COLORS:
        return {
            "color": _TRANSLATION_COLORS[cond.translation_m],
            "linestyle": _HEADING_STYLES.get(cond.heading_rad, "-."),
        }
    return {"color": _FALLBACK_COLORS[index % len(_FALLBACK_COLORS)], "linestyle": "-."}


def heatmap_text(cell: Cell | None) -> str:
    """A heat-map cell's label: the mean over its seeds and, below it, its 95 % interval (the
    table's own numbers, `intervals.cell_sample`), e.g. '0.91\\n[0.88, 0.94]'; '—' missing."""
    if cell is None or cell.mean is None:
        return MISSING
    text = f"{cell.mean:.2f}"
    if cell.low is not None and cell.high is not None:
        text += f"\n[{cell.low:.2f}, {cell.high:.2f}]"
    return text


def auc_heatmap(table: Table, path: Path) -> None:
    """The AUC table as a heat map, one panel per matching mode (the paper's Figure 13). Each
    cell shows its mean and 95 % interval (`heatmap_text`); the best beyond the noise of a
    column (the table's bold) is in bold."""
    modes = [MODE_LABELS[m] for m in MODES if any(r[2] == MODE_LABELS[m] for r in table.rows)]
    n_rows = max((sum(1 for r in table.rows if r[2] == mode) for mode in modes), default=1)
    n_cols = max(len(table.columns), 1)
    width = 1.2 + 0.95 * n_cols
    height = 1.0 + 0.62 * n_rows
    with matplotlib.style.context("default"):
        fig = _new_figure(width, height * len(modes) + 0.6)
        axes = fig.subplots(len(modes), 1, squeeze=False)[:, 0]
        cmap = matplotlib.colormaps["viridis"].with_extremes(bad="0.85")
        image = None
        for ax, mode in zip(axes, modes, strict=True):
            rows = [i for i, r in enumerate(table.rows) if r[2] == mode]
            values = np.full((len(rows), len(table.columns)), np.nan)
            for a, i in enumerate(rows):
                for j in range(len(table.columns)):
                    cell = table.cells[i][j]
                    if cell is not None and cell.mean is not None:
                        values[a, j] = cell.mean
            image = ax.imshow(
                np.ma.masked_invalid(values), cmap=cmap, vmin=0.5, vmax=1.0, aspect="auto"
            )
            for a, i in enumerate(rows):
                for j in range(len(table.columns)):
                    v = values[a, j]
                    color = "black" if np.isnan(v) or v > 0.8 else "white"
                    ax.text(j, a, heatmap_text(table.cells[i][j]), ha="center", va="center",
                            fontsize=7, color=color, linespacing=1.1,
                            fontweight="bold" if table.marks.get((i, j)) == BEST else "normal")
            ax.set_xticks(range(len(table.columns)), table.columns, fontsize=8)
            ax.set_yticks(
                range(len(rows)),
                [f"{table.rows[i][0]} v{table.rows[i][1]}" for i in rows],
                fontsize=8,
            )
            ax.set_title(f"{mode} matching", fontsize=9)
        if image is not None:
            fig.colorbar(image, ax=list(axes), label="ROC AUC", shrink=0.8)
        fig.suptitle(f"ROC AUC — {table.key.caption}", fontsize=9)
        save_png(fig, path)


def pr_figure(
    key: TableKey, method: str, version: str, records: Sequence[ResultRecord], path: Path
) -> None:
    """PR curves of one method, one curve per condition, a panel per matching mode (Figs. 10–12)."""
    by_mode: dict[str, list[ResultRecord]] = defaultdict(list)
    for record in records:
        for mode in record.results:
            by_mode[mode].append(record)
    modes = [m for m in MODES if m in by_mode]
    conditions = sorted({r.task.condition or "" for r in records})
    order = condition_order(conditions)
    n_seeds = len({r.seed for r in records})
    with matplotlib.style.context("default"):
        fig = _new_figure(5.0 * len(modes), 4.6)
        axes = fig.subplots(1, len(modes), squeeze=False)[0]
        for ax, mode in zip(axes, modes, strict=True):
            labelled: set[str] = set()
            for record in sorted(
                by_mode[mode], key=lambda r: (order.index(r.task.condition or ""), r.seed)
            ):
                name = record.task.condition or ""
                pr = record.results[mode].curves.pr
                style = _condition_style(name, order.index(name))
                ax.plot(
                    pr.recall,
                    pr.precision,
                    label=None if name in labelled else name,
                    **style,
                    **_seed_line(n_seeds),
                )
                labelled.add(name)
            _pr_axes(ax, f"{MODE_LABELS[mode]} matching")
            ax.legend(fontsize=7, ncols=2, loc="lower left")
        fig.suptitle(f"PR curves of {method} v{version} — {key.caption}{_seeds_caption(records)}",
                     fontsize=9)
        save_png(fig, path)


def revisit_pr_figure(key: TableKey, records: Sequence[ResultRecord], path: Path) -> None:
    """Revisit protocol PR curves: a panel per (matching mode, sequence), a curve per method."""
    sequences = sorted({r.task.sequence for r in records})
    modes = [m for m in MODES if any(m in r.results for r in records)]
    with matplotlib.style.context("default"):
        fig = _new_figure(4.4 * len(sequences), 4.0 * len(modes) + 0.4)
        axes = fig.subplots(len(modes), len(sequences), squeeze=False)
        methods = sorted({(r.method.name, shown_version(r)) for r in records})
        colors = matplotlib.colormaps["tab10"]
        n_seeds = len({r.seed for r in records})
        for a, mode in enumerate(modes):
            for b, sequence in enumerate(sequences):
                ax = axes[a][b]
                labelled: set[tuple[str, str]] = set()
                for record in sorted(
                    records, key=lambda r: (r.method.name, r.method.version, r.seed)
                ):
                    who = (record.method.name, shown_version(record))
                    if record.task.sequence != sequence or mode not in record.results:
                        continue
                    pr = record.results[mode].curves.pr
                    ax.plot(
                        pr.recall,
                        pr.precision,
                        color=colors(methods.index(who) % 10),
                        label=None if who in labelled else f"{who[0]} v{who[1]}",
                        **_seed_line(n_seeds),
                    )
                    labelled.add(who)
                _pr_axes(ax, f"sequence {sequence}, {MODE_LABELS[mode]} matching")
                if labelled:
                    ax.legend(fontsize=7, loc="lower left")
        fig.suptitle(f"Revisit protocol PR curves — {key.caption}{_seeds_caption(records)}",
                     fontsize=9)
        save_png(fig, path)


def _seed_line(n_seeds: int) -> dict[str, float]:
    """Line style of one record's PR curve: with several seeds every seed is drawn, thin and
    translucent, so where the curves of one condition fan out is the spread over the seeds."""
    return {"linewidth": 1.2} if n_seeds <= 1 else {"linewidth": 0.7, "alpha": 0.6}


def _seeds_caption(records: Sequence[ResultRecord]) -> str:
    """'' for one seed, else ' (one curve per seed: seeds 0-4)'."""
    seeds = {r.seed for r in records}
    return "" if len(seeds) <= 1 else f"\n(one curve per seed: seeds {format_seeds(frozenset(seeds))})"


def _pr_axes(ax: Axes, title: str) -> None:
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(0.0, 1.02)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_title(title, fontsize=9)
    ax.grid(True, linewidth=0.3)


def training_figure(logs: Sequence[TrainingLog], source: str, path: Path) -> None:
    """Validation AUC per epoch, a panel per method, a line per condition (the paper's Fig. 14)."""
    with matplotlib.style.context("default"):
        fig = _new_figure(5.0 * len(logs), 4.2)
        axes = fig.subplots(1, len(logs), squeeze=False, sharey=True)[0]
        for ax, log in zip(axes, logs, strict=True):
            order = condition_order(log.val_auc)
            for index, condition in enumerate(order):
                values = np.array(
                    [np.nan if v is None else v for v in log.val_auc[condition]], dtype=float
                )
                ax.plot(
                    log.epochs,
                    values,
                    marker=".",
                    linewidth=1.0,
                    label=condition,
                    **_condition_style(condition, index),
                )
            ax.set_xlabel("training iteration" if log.unit == "iteration" else "epoch")
            ax.set_ylabel(f"ROC AUC on {log.measured_on}" if log.measured_on else "validation ROC AUC",
                          fontsize=8 if log.measured_on else None)
            ax.set_title(log.method, fontsize=9)
            ax.grid(True, linewidth=0.3)
            ax.legend(fontsize=7, ncols=2, loc="lower right")
        fig.suptitle(f"Training stability — {source}", fontsize=9)
        save_png(fig, path)
