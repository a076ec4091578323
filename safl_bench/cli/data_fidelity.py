"""`safl-bench data fidelity`: the synthetic default against real KITTI, on BEVPlace's images.

Renders a synthetic sequence (default 00) in the BEV-density encoding (BEVPlace's images of its
scans, cached in the map cache), reads BEVPlace's images of the real sequences (`--bev-root`,
default 00 and 02), and prints the statistics of `safl_bench.analysis.fidelity` side by side: image
statistics, the difficulty curves of SAD and of the rotation-invariant polar descriptor against
distance (over all pairs, and over the pairs driving the same way) and heading difference, the
envelope excess of the synthetic curves, and the place-recognition results of the top-view
methods on the revisit protocol with Kendall's tau of their F1max ranking (records under
--results, and --records, are reused; missing cells are run and written to --results, except
BEVPlace's, about a second a frame on a CPU: run it first with `safl-bench run --method
bevplace ...`). Writes a PNG of the curves (--out) and, with --json,
the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench.cli.options import seed
from safl_bench.errors import DataError

HELP = ("compare the synthetic default (rendered as BEVPlace's images) with real KITTI top-view "
        "images: image statistics, difficulty curves, place-recognition ranking")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `data fidelity`."""
    parser.add_argument("--bev-root", metavar="DIR", default=None,
                        help="BEVPlace's image folders of real KITTI (data/KITTI; default $SAFL_BEV_ROOT)")
    parser.add_argument("--sequences", nargs="+", metavar="XX", default=["00", "02"],
                        help="real sequences to compare with (default: 00 02)")
    parser.add_argument("--synth-sequence", metavar="XX", default="00",
                        help="synthetic sequence (default 00, the default's test sequence)")
    parser.add_argument("--seed", type=seed, default=0, help="synthetic seed (default 0)")
    parser.add_argument("--data-version", metavar="V", default=None,
                        help="synthetic data version (default: the newest this safl-bench generates)")
    parser.add_argument("--synth-root", metavar="DIR", default=None,
                        help="a KITTI-layout root to take as the synthetic side instead of the default "
                             "(e.g. a changed generator's output); place recognition is then skipped")
    parser.add_argument("--step", type=int, default=1, help="use every STEP-th frame (default 1: all)")
    parser.add_argument("--json", metavar="FILE", default=None, help="also write the numbers as JSON")
    parser.add_argument("--out", metavar="PNG", default="fidelity.png", help="PNG of the curves (default %(default)s)")
    parser.add_argument("--results", metavar="DIR", default=None,
                        help="result records to reuse, and where missing cells are written "
                             "(default $SAFL_RESULTS or ./results)")
    parser.add_argument("--records", metavar="DIR", action="append", default=[],
                        help="more record folders to read (never written), e.g. leaderboard/records")
    parser.add_argument("--methods", nargs="+", metavar="NAME", default=None,
                        help="top-view methods to rank, NAME or NAME@VERSION (default: sad bigan@1 "
                             "stable_afl@1 bevplace, those registered)")
    parser.add_argument("--no-run", action="store_true", help="only read records; run no missing cell")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def _real_root(arg: str | None) -> Path:
    from safl_bench.sources.bev import BEV_ROOT_ENV

    value = arg if arg is not None else os.environ.get(BEV_ROOT_ENV)
    if not value:
        raise DataError(
            "data fidelity compares the synthetic default with real top-view images: pass --bev-root DIR "
            f"(BEVPlace's data/KITTI, with sequences 00 02) or set {BEV_ROOT_ENV}"
        )
    return Path(value).expanduser()


def _fmt(v: float | None, pct: bool = False, digits: int = 3) -> str:
    if v is None:
        return "n/a"
    return f"{100 * v:.1f} %" if pct else f"{v:.{digits}f}"


def _worst(edges: list[float], k: int | None, unit: str) -> str:
    """" (worst at A-B unit)" for bin k of `edges`, "" without a worst bin."""
    return "" if k is None else f" (worst at {edges[k]:g}-{edges[k + 1]:g} {unit})"


def _table(rows: list[list[str]]) -> str:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths, strict=True)))
             for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


#: Data seeds whose synthetic routes the report measures (poses only, no rendering).
ROUTE_SEEDS = range(5)


def _synth_task(current: str, version: str | None) -> str:
    """The revisit task of the synthetic sequence on data `version`: `current` (the newest
    data), else the highest registered version of that name on `version`."""
    from safl_bench.tasks.registry import latest_on_data, registry

    spec_ = registry[current]
    if version is None or spec_.data_version == version:
        return current
    return latest_on_data(spec_, version) or current


def _synth_routes(args: argparse.Namespace) -> dict[int, Any]:
    """Route measures of the synthetic sequence for each of `ROUTE_SEEDS` (cheap: no town)."""
    from safl_bench import synth
    from safl_bench.analysis.fidelity import route_measures

    version = args.data_version or synth.GENERATOR_VERSION
    out = {}
    for k in ROUTE_SEEDS:
        scene = synth.make_route(args.synth_sequence, k, version=version)
        out[k] = route_measures(scene.trajectory.xy, scene.trajectory.times)
    return out


def _route_text(r: Any) -> str:
    loops = "no loops" if r.loop_min_m is None else f"{r.loop_min_m:.0f} / {r.loop_median_m:.0f} m"
    return f"{100 * r.revisit_share:.1f} %, {100 * r.short_lap_share:.1f} %, {loops}"


def _route_rows(order: list[Any]) -> list[list[str]]:
    """Rows of the route measures of the measured sequences (n/a where they had no times)."""
    def cell(m: Any, key: str, pct: bool = False) -> str:
        value = None if m.route is None else getattr(m.route, key)
        if value is None:
            return "n/a"
        return _fmt(value, pct=True) if pct else f"{value:.0f}"

    return [["route length m", *[cell(m, "length_m") for m in order]],
            ["frames revisiting (5 m, > 30 s)", *[cell(m, "revisit_share", True) for m in order]],
            ["frames on a short lap (loop < 500 m)", *[cell(m, "short_lap_share", True) for m in order]],
            ["frames on a third pass", *[cell(m, "third_pass_share", True) for m in order]],
            ["shortest loop m", *[cell(m, "loop_min_m") for m in order]],
            ["median loop m", *[cell(m, "loop_median_m") for m in order]],
            ["median revisit gap s", *[cell(m, "gap_median_s") for m in order]]]


def _xy(edges: list[float], values: list[float | None]) -> tuple[np.ndarray, list[float]]:
    """Bin centres of `edges` and `values` with NaN for bins without a value, for plotting."""
    mids = (np.asarray(edges[:-1]) + np.asarray(edges[1:])) / 2
    return mids, [np.nan if v is None else v for v in values]


def _plot(path: Path, measured: list[Any], synth_label: str, pr: dict[str, Any], tasks: list[str]) -> None:
    import matplotlib

    from safl_bench.analysis.fidelity import LATERAL_BAND_M

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 4, figsize=(21, 9))
    for m in measured:
        synth = m.label == synth_label
        lw = 2.2 if synth else 1.4
        style: dict[str, Any] = {"color": "k", "lw": lw} if synth else {"lw": lw}
        st = m.stats
        axes[0, 0].plot(*_xy(st.radial_edges_m, st.radial_profile), label=m.label, **style)
        axes[0, 3].plot(*_xy(st.lateral_edges_m, st.lateral_occupancy), label=m.label, **style)
        for col, name in ((1, "sad"), (2, "polar")):
            c, same_way, h = m.distance[name], m.distance_same_way[name], m.heading[name]
            line, = axes[0, col].plot(*_xy(c.edges, c.values), marker=".", label=m.label, **style)
            axes[0, col].plot(*_xy(same_way.edges, same_way.values), ls="--", color=line.get_color(),
                              lw=lw * 0.7, label=f"{m.label}, same way")
            axes[1, col - 1].plot(*_xy(h.edges, h.values), marker="o", label=m.label, **style)
    axes[0, 0].set(title="radial profile: mean value by distance", xlabel="m from the sensor", ylabel="mean value")
    for col, name in ((1, "SAD (central 128 x 128)"), (2, "polar (20 x 60, shift-invariant)")):
        axes[0, col].set(title=f"{name}: difference vs distance", xlabel="distance between frames (m)",
                         ylabel="median difference / median beyond 100 m")
        axes[0, col].axhline(1.0, color="grey", lw=0.6)
        axes[1, col - 1].set(title=f"{name.split(' (')[0]}: vs heading difference, pairs within 3 m",
                             xlabel="heading difference (deg)", ylabel="median difference / median beyond 100 m")
    axes[0, 3].set(title=f"lateral occupancy (within {LATERAL_BAND_M:g} m ahead and behind)",
                   xlabel="m left of the sensor (negative: right)", ylabel="share of non-zero pixels")
    _plot_ranking(axes[1, 2], pr, tasks)
    axes[1, 3].axis("off")
    for a in axes.ravel():
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize=7)
    fig.tight_layout()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=80)
    except OSError as exc:
        raise DataError(f"cannot write {path}: {exc}") from exc
    finally:
        plt.close(fig)


def _plot_ranking(ax: Any, pr: dict[str, Any], tasks: list[str]) -> None:
    """Bars of the methods' single-frame F1max per task."""
    methods = sorted(pr)
    width = 0.8 / max(1, len(tasks))
    for k, task in enumerate(tasks):
        vals = [np.nan if pr[m].get(task) is None or pr[m][task].f1_max is None else pr[m][task].f1_max
                for m in methods]
        ax.bar(np.arange(len(methods)) + k * width, vals, width, label=task.split("/")[-1])
    ax.set_xticks(np.arange(len(methods)) + width * (len(tasks) - 1) / 2, methods)
    ax.set(title="single-frame F1max, revisit protocol", ylim=(0, 1))


def _order_text(order: Any) -> str:
    """'-0.044 [-0.127, 0.023] tied' (or '... stable_afl > bigan'); 'n/a tied' without outcomes."""
    iv = order.difference
    shown = "n/a (no per-query outcomes)" if iv is None else iv.format(1.0, 3)
    return f"{shown} {'tied' if order.order == 0 else order.verdict.removesuffix(' resolved')}"


def _order_rows(orders: dict[str, list[Any]], tasks: list[str]) -> list[list[str]]:
    """A row per pair of methods, a column per task: the difference, its interval, the verdict."""
    pairs = sorted({(o.first, o.second) for per in orders.values() for o in per})
    rows = [["pair (first - second)", *[t.split("/")[-1] for t in tasks]]]
    for a, b in pairs:
        cells = []
        for t in tasks:
            found = [o for o in orders.get(t, []) if (o.first, o.second) == (a, b)]
            cells.append(_order_text(found[0]) if found else "n/a")
        rows.append([f"{a} - {b}", *cells])
    return rows


def _order_json(order: Any) -> dict[str, Any]:
    iv = order.difference
    return {"first": order.first, "second": order.second, "order": order.order,
            "verdict": order.verdict,
            "difference": None if iv is None else {"mean": iv.mean, "low": iv.low, "high": iv.high}}


def _ranking(args: argparse.Namespace) -> list[Any]:
    """The synthetic-against-real comparisons (`safl_bench.leaderboard.ranking`) of the records
    under --results and --records (--results wins for a cell in both)."""
    from safl_bench.leaderboard.ranking import comparisons
    from safl_bench.results.records import default_results_dir, load_records

    folders = [*(Path(p).expanduser() for p in args.records),
               Path(args.results).expanduser() if args.results else default_results_dir()]
    by_key: dict[Any, Any] = {}
    for folder in folders:
        if folder.is_dir():
            for record in load_records(folder)[0]:
                by_key[record.key] = record
    return comparisons(list(by_key.values()))


def main(args: argparse.Namespace) -> int:
    from safl_bench.analysis import fidelity as F
    from safl_bench.common.fingerprint import to_jsonable
    from safl_bench.methods.method import list_methods, method_class
    from safl_bench.results.records import default_results_dir
    from safl_bench.sources import bev_source, synth_source
    from safl_bench.tasks import spec
    from safl_bench.tasks.builtin import revisit_id
    from safl_bench.views import mapcache
    from safl_bench.views.mapbuild import select_frames
    from safl_bench.views.mapconfig import bev_density_config
    from safl_bench.views.noise import CLEAN

    started = time.perf_counter()
    if args.step < 1:
        raise DataError(f"--step must be >= 1, got {args.step}")
    root = _real_root(args.bev_root)
    for name in args.methods or ():
        method_class(name)  # an unknown name or version fails before any work
    real = bev_source(root)
    for name in args.sequences:  # every requested sequence is there before any work
        real.sequence(str(name))
    progress = not args.quiet

    config = bev_density_config()
    if args.synth_root is not None:
        from safl_bench.sources import kitti_source

        synth: Any = kitti_source(args.synth_root)
    else:
        synth = synth_source(args.seed, [args.synth_sequence], progress=progress,
                             version=args.data_version)
    sseq = synth.sequence(args.synth_sequence)
    frames = select_frames(len(sseq), args.step)
    views = mapcache.load_views(synth, args.synth_sequence, config, frames=frames, condition=CLEAN,
                                seed=0, progress=progress)
    synth_label = f"synthetic {args.synth_sequence}" if args.synth_root is None else f"{args.synth_root} {args.synth_sequence}"
    data = [F.SequenceImages(synth_label, np.asarray(views), sseq.positions[frames], sseq.headings[frames],
                             sseq.times[frames])]
    for name in args.sequences:
        seq = real.sequence(str(name))
        images = real.images(str(name), progress=progress)
        if images.shape[1] != config.size:
            raise DataError(f"{seq.folder / 'imgs'}: images are {images.shape[1]}x{images.shape[1]}, "
                            f"not BEVPlace's {config.size}x{config.size}")
        data.append(F.SequenceImages(f"real {name}", images[::args.step], seq.positions[::args.step],
                                     seq.headings[::args.step], seq.times[::args.step]))
    measured = [F.measure(d, config.cell_m) for d in data]
    del data, views
    synth_m, real_m = measured[0], measured[1:]
    def envelope(curves: str) -> dict[str, tuple[float, int | None]]:
        """Per descriptor, the envelope excess of the synthetic curves `curves` (a field of
        `SequenceFidelity`) against the real ones, and its worst bin."""
        return {name: F.envelope_excess(getattr(synth_m, curves)[name], [getattr(m, curves)[name] for m in real_m])
                for name in F.DESCRIPTORS}

    excess, heading_excess, same_way_excess = (envelope(c) for c in ("distance", "heading", "distance_same_way"))
    curves_s = time.perf_counter() - started

    registered = {m.name for m in list_methods()}
    methods = [m for m in (args.methods or F.TOPVIEW_METHODS)
               if args.methods or m.partition("@")[0] in registered]
    synth_task = _synth_task(revisit_id("synth", args.synth_sequence), getattr(synth, "version", None))
    routes = _synth_routes(args) if args.synth_root is None else {}
    real_tasks = [revisit_id("bev", str(s)) for s in args.sequences]
    pr: dict[str, dict[str, F.MethodResult]] = {}
    taus: dict[str, float | None] = {"mean": None}
    if args.synth_root is None:
        for task_id in [synth_task, *real_tasks]:
            spec(task_id)  # one line naming an unregistered task (e.g. a real sequence without one)
        results_dir = Path(args.results).expanduser() if args.results else default_results_dir()
        pr = F.place_recognition(methods, synth_task, real_tasks, results_dir=results_dir,
                                 extra_record_dirs=[Path(p).expanduser() for p in args.records],
                                 bev_root=str(root), run=not args.no_run, progress=progress)
        taus = F.ranking_tau(pr, synth_task, real_tasks)
    runtime = time.perf_counter() - started
    targets = F.goals(excess["sad"][0], [m.stats.nonzero_fraction for m in real_m],
                      synth_m.stats.nonzero_fraction, taus.get("mean"))

    # -- the table ------------------------------------------------------------------------
    labels = [m.label for m in real_m] + [synth_m.label]
    order = [*real_m, synth_m]
    rows = [["", *labels]]
    rows.append(["frames", *[str(m.frames) for m in order]])
    rows.append(["non-zero pixels", *[_fmt(m.stats.nonzero_fraction, pct=True) for m in order]])
    rows.append(["mean non-zero value", *[_fmt(m.stats.mean_nonzero) for m in order]])
    edges = synth_m.stats.radial_edges_m
    for k in range(0, len(edges) - 1, 2):
        rows.append([f"mean value at {edges[k]:g}-{edges[k + 1]:g} m",
                     *[_fmt(m.stats.radial_profile[k], digits=4) for m in order]])
    lat = synth_m.stats.lateral_edges_m
    for k in range(len(lat) - 1):
        if abs(lat[k]) <= 12 and abs(lat[k + 1]) <= 12:
            side = "left" if lat[k] >= 0 else "right"
            lo, hi = sorted((abs(lat[k]), abs(lat[k + 1])))
            rows.append([f"non-zero {lo:g}-{hi:g} m {side}",
                         *[_fmt(m.stats.lateral_occupancy[k], pct=True) for m in order]])
    for name, title in (("sad", "SAD"), ("polar", "polar")):
        c_edges = synth_m.distance[name].edges
        for k in range(len(c_edges) - 1):
            rows.append([f"{title} difference {c_edges[k]:g}-{c_edges[k + 1]:g} m",
                         *[_fmt(m.distance[name].values[k]) for m in order]])
        for k in range(min(3, len(c_edges) - 1)):
            rows.append([f"{title} difference {c_edges[k]:g}-{c_edges[k + 1]:g} m, same way",
                         *[_fmt(m.distance_same_way[name].values[k]) for m in order]])
        h_edges = synth_m.heading[name].edges
        for k in range(len(h_edges) - 1):
            rows.append([f"{title} at same place, turned {h_edges[k]:g}-{h_edges[k + 1]:g} deg",
                         *[_fmt(m.heading[name].values[k]) + f" ({m.heading[name].counts[k]})" for m in order]])
        rows.append([f"{title} median difference beyond 100 m", *[_fmt(m.distance[name].far_median, digits=4) for m in order]])
        rows.append([f"{title} far pairs alike (below {F.ALIAS_REF_M[0]:g}-{F.ALIAS_REF_M[1]:g} m same way)",
                     *[_fmt(m.alias_share[name], pct=True) for m in order]])
    rows += _route_rows(order)
    print(f"fidelity: {synth_m.label} (seed {args.seed}, BEV-density encoding) against BEVPlace's images of "
          f"{', '.join(labels[:-1])} under {root}; every {args.step if args.step > 1 else ''}"
          f"{'th ' if args.step > 1 else ''}frame")
    print(_table(rows))
    if routes:
        print(f"routes of the synthetic {args.synth_sequence}, data seeds {min(routes)}-{max(routes)} "
              "(poses only; revisit %, short-lap %, shortest / median loop m):")
        print("  " + "; ".join(f"seed {k}: {_route_text(r)}" for k, r in routes.items()))
    for name, title in (("sad", "SAD"), ("polar", "polar")):
        value, kb = excess[name]
        where = _worst(synth_m.distance[name].edges, kb, "m")
        hv, hk = heading_excess[name]
        hwhere = _worst(synth_m.heading[name].edges, hk, "deg")
        sv, sk = same_way_excess[name]
        swhere = _worst(synth_m.distance_same_way[name].edges, sk, "m")
        print(f"{title} curve envelope excess: {value:.3f}{where}; pairs driving the same way "
              f"(within {F.SAME_WAY_DEG:g} deg): {sv:.3f}{swhere}; against heading: {hv:.3f}{hwhere}")
    print()
    tasks = [*real_tasks, synth_task]
    prow = [["method", *[f"{t.split('/')[-1]} R@1 / F1max" for t in tasks]]]
    for m in sorted(pr):
        cells = []
        for t in tasks:
            r = pr[m].get(t)
            cells.append("n/a" if r is None or r.f1_max is None else f"{_fmt(r.recall_at_1)} / {_fmt(r.f1_max)}")
        prow.append([m, *cells])
    if pr:
        print("place recognition, revisit protocol, single-frame matching (Recall@1 / F1max):")
        print(_table(prow))
    else:
        print(f"place recognition skipped: {args.synth_root} is not the registered synthetic default")
    notes = sorted({f"{r.method}: {r.note}" for per in pr.values() for r in per.values() if r.note})
    for note in notes:
        print(f"  note: {note}")
    for m, used in F.mixed_weights(pr).items():
        groups: dict[str, list[str]] = {}
        for t, w in used.items():
            groups.setdefault(w or "no weights", []).append(t.split("/")[-1].split("-")[0])
        print(f"  note: {m} ran with other weights on other tasks ("
              + "; ".join(f"{w} on {', '.join(ts)}" for w, ts in groups.items())
              + "): its rank compares trainings as well as data; for the data alone, run it on the "
              f"real tasks with the synthetic weights (`safl-bench run --method {m} --weights FILE "
              "--results DIR ...`) and give --results DIR here")
    orders = {t: F.pair_orders(pr, t) for t in tasks} if pr else {}
    if any(orders.values()):
        print("paired differences of single-frame F1max (first - second, 95 % interval over the "
              "queries, block bootstrap); an order counts only when its interval excludes 0, "
              "else the pair is tied:")
        print(_table(_order_rows(orders, tasks)))
    print("Kendall tau-b of the orders beyond the noise (ties counted), synthetic vs " + ", ".join(
        f"{t.split('/')[-1] if t != 'mean' else 'the real mean'} {_fmt(v)}" for t, v in taus.items()))
    if any(orders.values()) and any(v is None for v in taus.values()):
        print("  (n/a: on one side every pair of the methods both sides have is tied, so there is "
              "no order to correlate)")
    comps = _ranking(args) if pr else []
    if comps:
        from safl_bench.leaderboard import ranking

        rows = ranking.summary_rows(comps)
        print("the default's order of the methods against real KITTI's, from the records "
              "(Recall@1 %, mean over each protocol's tasks; tau-b with its 95 % interval over "
              "seeds and queries; `safl_bench.leaderboard.ranking`):")
        print(_table([[r[0], r[1], r[2], r[5], r[6], r[3] + "  |  " + r[4]] for r in rows]))
        for line in ranking.notes(comps):
            print(f"  note: {line}")
    print("goals: " + "; ".join(
        f"{g.name} {_fmt(g.value, pct=g.name == 'nonzero_fraction')} (goal {g.target}): {'met' if g.met else 'NOT met'}"
        for g in targets))
    print(f"runtime {runtime:.1f} s (curves and statistics {curves_s:.1f} s)")

    out = Path(args.out).expanduser()
    _plot(out, measured, synth_label, pr, tasks)
    print(f"wrote {out}")
    if args.json:
        report: dict[str, Any] = {
            "curve_envelope_excess": excess["sad"][0],
            "curve_envelope_excess_polar": excess["polar"][0],
            "heading_envelope_excess": {n: heading_excess[n][0] for n in F.DESCRIPTORS},
            "same_way_envelope_excess": {n: same_way_excess[n][0] for n in F.DESCRIPTORS},
            "nonzero_fraction": {"real": {m.label.split()[-1]: m.stats.nonzero_fraction for m in real_m},
                                 "synthetic": synth_m.stats.nonzero_fraction},
            "mean_nonzero": {"real": {m.label.split()[-1]: m.stats.mean_nonzero for m in real_m},
                             "synthetic": synth_m.stats.mean_nonzero},
            "ranking_tau": taus.get("mean"),
            "routes": {m.label: to_jsonable(m.route) for m in measured},
            "synthetic_routes_by_seed": {str(k): to_jsonable(r) for k, r in routes.items()},
            "alias_share": {m.label: m.alias_share for m in measured},
            "goals": {g.name: {"value": g.value, "target": g.target, "met": g.met} for g in targets},
            "ranking_comparisons": [c.to_json() for c in comps],
            "ranking_tau_per_sequence": {t: v for t, v in taus.items() if t != "mean"},
            "place_recognition": {m: {t: r.to_json() for t, r in per.items()} for m, per in pr.items()},
            "pair_orders": {t: [_order_json(o) for o in per] for t, per in orders.items()},
            "sequences": {m.label: to_jsonable(m) for m in measured},
            "synthetic": {"seed": args.seed, "sequence": args.synth_sequence, "root": str(synth.root),
                          "data_version": getattr(synth, "version", None), "task": synth_task,
                          "map_config": to_jsonable(config)},
            "real_root": str(root),
            "step": args.step,
            "runtime_s": runtime,
        }
        path = Path(args.json).expanduser()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(report, indent=1, sort_keys=True) + "\n")
        except OSError as exc:
            raise DataError(f"cannot write {path}: {exc}") from exc
        print(f"wrote {path}")
    return 0
