"""The matcher's scaling curve on the board: the runs of ``safl-bench bench matcher --json``
committed under ``experiments/matcher-scaling/``, as a table and a figure (time and peak memory
against frames, per mode, with the dense path where it fit).

Each file is one run of the benchmark (one size, one mode). The board shows what the files
hold; it measures nothing. A file that is not such a run is named in one line and left out.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from safl_bench.results.records import Problem

#: Where the runs live, relative to the leaderboard directory.
FOLDER = "experiments/matcher-scaling"
MD = "tables/matcher-scaling.md"
PNG = "figures/matcher-scaling.png"
TITLE = "Matcher scaling: descriptors to matches, N queries against N database frames"
INTRO = ("Each row is one run of `safl-bench bench matcher --n N --dim D --mode MODE --json FILE` "
         "on the 2-core development machine: seeded random descriptors with a planted route "
         "(`safl_bench.bench.matching_bench`). *seconds*: median over the run's repeats; "
         "*peak MB*: the process's extra resident memory during its first run; *route found*: share "
         "of the planted queries matched to their frame +- 1; *same as dense*: the exact mode's "
         "matches, scores and velocities, or the candidate mode's matched frames, against the "
         "whole-matrix path timed in the same run (n/a where its two N x N matrices do not fit); "
         "half of the queries are new places, whose best sequence need not pass through their K "
         "nearest frames, so about half of the candidate mode's answers differ there. Timings on "
         "a shared machine: compare ratios within a run, not across rows.")
_KEYS = ("frames", "dim", "mode", "seconds", "peak_mb", "route_found", "identical_to_dense")


def load(folder: Path) -> tuple[list[dict[str, Any]], list[Problem]]:
    """The runs under `folder` (none when it does not exist), sorted by mode, dim, frames; and
    one Problem per file that is not a run of the benchmark."""
    runs: list[dict[str, Any]] = []
    problems: list[Problem] = []
    if not folder.is_dir():
        return runs, problems
    for path in sorted(folder.glob("*.json")):
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            problems.append(Problem(path, f"not a matcher benchmark run: {exc}"))
            continue
        missing = [k for k in _KEYS if not isinstance(data, dict) or k not in data]
        if missing:
            problems.append(Problem(path, f"not a matcher benchmark run: no {', '.join(missing)}"))
            continue
        data["file"] = path.name
        runs.append(data)
    runs.sort(key=lambda r: (r["mode"] != "exact", r.get("index") or "", r.get("k") or 0,
                             r["dim"], r["frames"]))
    return runs, problems


def _mode(run: dict[str, Any]) -> str:
    if run["mode"] == "candidates":
        return f"candidates (k={run.get('k')}, {run.get('index')})"
    return "exact (blocks)"


def rows(runs: list[dict[str, Any]]) -> list[list[str]]:
    """The table's header and rows."""
    out = [["frames", "dim", "mode", "seconds", "peak MB", "route found", "same as dense",
            "dense seconds", "dense peak MB", "load avg", "file"]]
    for r in runs:
        dense = r.get("dense") or {}
        same = r["identical_to_dense"]
        env = (r.get("timing") or {}).get("env") or {}
        load = env.get("load_avg_1m")
        out.append([f"{r['frames']:,}", str(r["dim"]), _mode(r), f"{r['seconds']:.2f}",
                    "n/a" if r["peak_mb"] is None else f"{r['peak_mb']:.0f}",
                    f"{100 * r['route_found']:.1f} %",
                    "n/a" if same is None else ("yes" if same else
                                                f"no ({100 * r.get('agree_with_dense', 0):.1f} % same frame)"),
                    f"{dense['seconds']:.2f}" if dense else "n/a",
                    f"{dense['peak_mb']:.0f}" if dense and dense.get("peak_mb") is not None else "n/a",
                    "n/a" if load is None else f"{load:.1f}", f"`{r['file']}`"])
    return out


def markdown(runs: list[dict[str, Any]]) -> str:
    """The table as the board's Markdown page."""
    table = rows(runs)
    lines = [f"# {TITLE}", "", INTRO, "", "| " + " | ".join(table[0]) + " |",
             "|" + "---|" * len(table[0])]
    lines += ["| " + " | ".join(r) + " |" for r in table[1:]]
    return "\n".join(lines) + "\n"


def figure(runs: list[dict[str, Any]], path: Path) -> None:
    """Seconds and peak MB against frames (log-log), a line per mode and dim, the dense path's
    points where it ran (`figures`' canvas and PNG writer: the same runs, the same bytes)."""
    import matplotlib.style

    from safl_bench.leaderboard.figures import _new_figure, save_png

    series: dict[str, list[dict[str, Any]]] = {}
    dense: dict[int, set[tuple[int, float, float]]] = {}
    for r in runs:
        series.setdefault(f"{_mode(r)}, {r['dim']}-d", []).append(r)
        if r.get("dense"):
            dense.setdefault(r["dim"], set()).add(
                (r["frames"], r["dense"]["seconds"], r["dense"].get("peak_mb") or float("nan")))
    with matplotlib.style.context("default"):
        fig = _new_figure(11, 4.4)
        axes = fig.subplots(1, 2)
        for label, items in sorted(series.items()):
            items.sort(key=lambda r: r["frames"])
            n = [r["frames"] for r in items]
            axes[0].plot(n, [r["seconds"] for r in items], "o-", label=label)
            axes[1].plot(n, [r["peak_mb"] or float("nan") for r in items], "o-", label=label)
        for dim, pts in sorted(dense.items()):
            ordered = sorted(pts)
            for ax, col in ((axes[0], 1), (axes[1], 2)):
                ax.plot([p[0] for p in ordered], [p[col] for p in ordered], "k^--",
                        label=f"dense (whole matrix), {dim}-d")
        for ax, what in zip(axes, ("seconds, descriptors to matches", "peak extra memory (MB)"),
                            strict=True):
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("frames (queries = database)")
            ax.set_ylabel(what)
            ax.grid(True, which="both", alpha=0.3)
        axes[0].legend(fontsize=8)
        fig.suptitle("Matcher scaling on the 2-core development machine (safl-bench bench matcher)")
        save_png(fig, path)
