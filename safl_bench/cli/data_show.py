"""`safl-bench data show`: draw a sequence to PNG: its route with revisits, scans, top-view maps."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from safl_bench.cli.options import seed
from safl_bench.errors import DataError

HELP = "draw a sequence (route with revisits, bird's-eye scans, top-view maps) to a PNG"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `data show`."""
    parser.add_argument("--root", metavar="DIR", default=None,
                        help="dataset root in the KITTI odometry layout (default: the synthetic "
                             "default of --seed, generated if missing)")
    parser.add_argument("--sequence", default="00", help="sequence to draw (default 00)")
    parser.add_argument("--out", metavar="PNG", default=None,
                        help="image to write (default: show-<sequence>.png in the current folder)")
    parser.add_argument("--seed", type=seed, default=0, help="synthetic seed when --root is not given")
    parser.add_argument("--scans", type=int, default=3, help="number of scans and maps shown (default 3)")


def revisit_masks(seq) -> tuple[np.ndarray, np.ndarray]:
    """Frames revisiting an older place in the same / the opposite direction."""
    from safl_bench.synth.routes import revisit_kinds

    return revisit_kinds(seq.positions, seq.headings, seq.times)


def draw_route(ax, seq) -> None:
    """The route coloured by time, with its revisits highlighted."""
    xy = seq.positions
    same, opposite = revisit_masks(seq)
    pts = ax.scatter(xy[:, 0], xy[:, 1], c=seq.times, s=2, cmap="viridis", zorder=1)
    ax.scatter(xy[same, 0], xy[same, 1], s=9, c="tab:red", zorder=2,
               label=f"revisit, same direction ({int(same.sum())} frames)")
    ax.scatter(xy[opposite, 0], xy[opposite, 1], s=9, c="tab:orange", marker="x", zorder=3,
               label=f"revisit, opposite direction ({int(opposite.sum())} frames)")
    ax.plot(*xy[0], "k^", ms=9, label="start", zorder=4)
    ax.set_aspect("equal")
    ax.set_title(f"sequence {seq.name}: route ({len(seq)} scans, {seq.times[-1]:.0f} s)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize=7)
    ax.figure.colorbar(pts, ax=ax, label="time (s)", shrink=0.7)


def draw_scan(ax, points: np.ndarray, title: str, extent: float = 40.0) -> None:
    """Bird's-eye view of one scan, coloured by height."""
    near = (np.abs(points[:, 0]) < extent) & (np.abs(points[:, 1]) < extent)
    p = points[near]
    order = np.argsort(p[:, 2])
    ax.scatter(p[order, 0], p[order, 1], c=p[order, 2], s=0.3, cmap="turbo", vmin=-2.0, vmax=2.5,
               linewidths=0)
    ax.set_xlim(-extent, extent)
    ax.set_ylim(-extent, extent)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.tick_params(labelsize=7)


def top_views(seq, frames: np.ndarray) -> np.ndarray | None:
    """Top-view maps (F, H, W) of `frames` with the default MapConfig (helper B's map builder)."""
    from safl_bench.mapbuild import build_views
    from safl_bench.mapconfig import MapConfig

    views = build_views(seq, MapConfig(), frames, {"clean": None}, ["topview"], progress=False)
    return np.asarray(views["clean", "topview"])


def main(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from safl_bench.sources.kitti import open_sequence

    name = str(args.sequence)
    if args.scans < 1 or args.scans > 8:
        raise DataError(f"--scans must be between 1 and 8, got {args.scans}")
    out = Path(args.out).expanduser() if args.out else Path(f"show-{name}.png")
    if out.is_dir():
        raise DataError(f"--out {out} is a directory; give a .png file name")
    if args.root is None:
        from safl_bench import synth

        if name not in synth.ALL_SEQUENCES:
            raise DataError(f"unknown synthetic sequence {name!r}; known: {' '.join(synth.ALL_SEQUENCES)}")
        root = synth.default_root(args.seed)
        synth.ensure(root, [name], seed=args.seed)
    else:
        root = Path(args.root).expanduser()
    seq = open_sequence(root, name)
    n = args.scans
    frames = np.linspace(0, len(seq) - 1, n + 2).round().astype(np.int64)[1:-1]
    maps = top_views(seq, frames)

    fig = plt.figure(figsize=(4.2 * (n + 2), 8.4))
    grid = fig.add_gridspec(2, n + 2)
    draw_route(fig.add_subplot(grid[:, :2]), seq)
    xy = seq.positions
    route_ax = fig.axes[0]
    for k, i in enumerate(frames):
        route_ax.annotate(f"#{i}", xy[i], fontsize=8, xytext=(4, 4), textcoords="offset points")
        pts = seq.scan(int(i))
        draw_scan(fig.add_subplot(grid[0, 2 + k]), pts, f"scan {i}: {len(pts)} points (colour = z, forward = +x)")
        ax = fig.add_subplot(grid[1, 2 + k])
        if maps is not None:
            ax.imshow(maps[k], cmap="gray", vmin=0, vmax=1)
            ax.set_title(f"top-view map at scan {i} (forward = up)", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{root} - sequence {name}", fontsize=10)
    fig.tight_layout()
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=90)
    except OSError as exc:
        raise DataError(f"cannot write {out}: {exc}") from exc
    finally:
        plt.close(fig)
    print(f"wrote {out}")
    return 0
