"""Pictures of the loop-closure stage (`safl_bench.slam`), drawn as the project's other figures
(`figures._new_figure`, `figures.save_png`: matplotlib's object API on Agg, atomic writes).

* `trajectory_figure`: one cell: ground truth, odometry alone and each back-end's optimised
  trajectory, the accepted closures as lines between their two true positions, true ones green
  and false ones red, drawn between their two poses on the odometry's trajectory (the drift the
  closure has to undo; on the ground truth a true closure's ends would coincide).
* `curve_figure`: ATE against the threshold of several methods on one axis (one panel per
  back-end), the x axis the closures accepted, from none to every match: thresholds of different
  methods are on different scales, the number of closures is not.
* `ate_bars`: the leaderboard's per-task ATE of each method and back-end at the deployed
  threshold, with the 95 % interval over seeds and the odometry alone as a line.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from safl_bench.leaderboard.figures import _new_figure, save_png
from safl_bench.leaderboard.slam_table import SlamCell
from safl_bench.slam.backend import BACKENDS
from safl_bench.slam.cell import CellTrajectories, SlamResult, seed_interval

BACKEND_COLOURS = {"least-squares": "tab:blue", "cauchy": "tab:orange", "gnc-tls": "tab:purple"}


def trajectory_figure(cell: CellTrajectories, path: Path) -> None:
    """The cell's trajectories and closures (module doc), written to `path` as PNG."""
    r = cell.result
    fig = _new_figure(9.0, 8.0)
    ax = fig.add_subplot(1, 1, 1)
    truth, closures = cell.truth, cell.closures
    for flag, colour, label in ((True, "tab:green", "true closure"), (False, "tab:red", "false closure")):
        pick = closures.true == flag
        if pick.any():
            q, m = cell.odometry[closures.query[pick], :2], cell.odometry[closures.match[pick], :2]
            segments = np.stack([q, m], axis=1)
            xs = np.column_stack([segments[:, :, 0], np.full(len(segments), np.nan)]).ravel()
            ys = np.column_stack([segments[:, :, 1], np.full(len(segments), np.nan)]).ravel()
            ax.plot(xs, ys, color=colour, lw=0.8, alpha=0.8,
                    label=f"{label} ({int(pick.sum())})", zorder=1)
    ax.plot(truth[:, 0], truth[:, 1], color="black", lw=1.6, label="ground truth", zorder=2)
    ax.plot(cell.odometry[:, 0], cell.odometry[:, 1], color="grey", lw=1.0, ls="--",
            label=f"odometry alone (ATE {r.odometry_ate_m:.2f} m)", zorder=2)
    for b in r.backends:
        trajectory = cell.optimised.get(b.backend)
        if trajectory is None:
            ax.plot([], [], color=BACKEND_COLOURS.get(b.backend), label=f"{b.backend}: did not converge")
            continue
        ax.plot(trajectory[:, 0], trajectory[:, 1], color=BACKEND_COLOURS.get(b.backend), lw=1.0,
                label=f"{b.backend} (ATE {b.ate_m:.2f} m)", zorder=3)
    threshold = "no closure" if r.threshold is None else f"threshold {r.threshold:.4g}"
    title = (f"{r.method} on {r.task}, SLAM seed {r.slam_seed}, {r.settings['mode']} matches, "
             f"{threshold} ({r.threshold_rule}); drift {r.drift['level']}; trajectories "
             "unaligned, from the true start")
    # wrapped to the figure's width (about 120 characters of 8 pt on 9 inches): a long threshold
    # rule used to run off the picture
    ax.set_title("\n".join(textwrap.wrap(title, 110)), fontsize=8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7, loc="best")
    save_png(fig, path)


def curve_figure(curves: Mapping[str, Sequence[SlamResult]], path: Path) -> None:
    """ATE against closures accepted for each method's curve (module doc), one panel per back-end."""
    fig = _new_figure(4.2 * len(BACKENDS), 4.0)
    first = next(iter(curves.values()))[0]
    for k, backend in enumerate(BACKENDS):
        ax = fig.add_subplot(1, len(BACKENDS), k + 1)
        for method, curve in curves.items():
            x = [c.closures_true + c.closures_false for c in curve]
            y = [c.ate(backend) for c in curve]
            line = ax.plot(x, y, marker="o", ms=3, label=method)[0]
            false_at = [c.closures_false > 0 for c in curve]
            if any(false_at):
                ax.plot([v for v, f in zip(x, false_at, strict=True) if f],
                        [v for v, f in zip(y, false_at, strict=True) if f], ls="none", marker="x",
                        ms=5, color=line.get_color())
        ax.axhline(first.odometry_ate_m, color="grey", ls="--", lw=0.8, label="odometry alone")
        ax.set_xscale("symlog", linthresh=10)
        ax.set_xlim(left=0)
        ax.set_title(backend, fontsize=9)
        ax.set_xlabel("closures accepted (x: some false)")
        if k == 0:
            ax.set_ylabel("ATE RMSE (m)")
            ax.legend(fontsize=7)
    fig.suptitle(f"{first.task}: ATE against the threshold, SLAM seed {first.slam_seed}, "
                 f"drift {first.drift['level']}", fontsize=9)
    save_png(fig, path)


def ate_bars(cells: Sequence[SlamCell], path: Path) -> None:
    """Per task, each (method, mode)'s ATE per back-end with its 95 % interval over seeds."""
    tasks = sorted({c.task for c in cells})
    fig = _new_figure(max(6.0, 1.2 * len(cells) / max(1, len(tasks)) + 2), 3.2 * len(tasks))
    for t, task in enumerate(tasks):
        ax = fig.add_subplot(len(tasks), 1, t + 1)
        group = sorted((c for c in cells if c.task == task), key=lambda c: (c.mode != "sequence", c.method))
        width = 0.8 / len(BACKENDS)
        for k, backend in enumerate(BACKENDS):
            intervals = [seed_interval(c.ate(backend)) for c in group]
            mean = np.array([i.mean for i in intervals])
            err = np.array([[i.mean - i.low for i in intervals], [i.high - i.mean for i in intervals]])
            ax.bar(np.arange(len(group)) + (k - 1) * width, mean, width, yerr=np.nan_to_num(err),
                   color=BACKEND_COLOURS[backend], label=backend, capsize=2)
        ax.axhline(seed_interval(group[0].ate(None)).mean, color="grey", ls="--", lw=0.8,
                   label="odometry alone")
        ax.set_xticks(np.arange(len(group)))
        ax.set_xticklabels([f"{c.method}\n{c.mode.replace('_', '-')}" for c in group], fontsize=7)
        ax.set_ylabel("ATE RMSE (m)")
        ax.set_title(f"{task}: deployed threshold, mean over SLAM seeds [95 % interval]", fontsize=9)
        if t == 0:
            ax.legend(fontsize=7)
    save_png(fig, path)
