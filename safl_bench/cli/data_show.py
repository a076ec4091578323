"""`safl-bench data show`: draw a sequence to PNG: its route with revisits, scans, top-view maps.

Rows, one column per shown frame: the scan from above (colour = height), the paper's top view
(local map of the last K scans -> occupancy, the default `MapConfig`), with `--density` the
BEV-density view (BEVPlace's encoding, `bev_density_config()`), and with `--bev-root` the
image BEVPlace published for the same frame, titled with how far the density view is from it
(IoU of the non-zero pixels, share of equal pixels). `--beside-synth` adds the same rows for
the same frame numbers of the synthetic default, so real scans and the default can be looked
at side by side through one pipeline.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from safl_bench.cli.options import seed
from safl_bench.errors import DataError

HELP = "draw a sequence (route with revisits, bird's-eye scans, top-view maps) to a PNG"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `data show`."""
    parser.add_argument("--root", "--kitti-root", dest="root", metavar="DIR", default=None,
                        help="dataset root in the KITTI odometry layout (default: the synthetic "
                             "default of --seed, generated if missing)")
    parser.add_argument("--sequence", default="00", help="sequence to draw (default 00)")
    parser.add_argument("--out", metavar="PNG", default=None,
                        help="image to write (default: show-<sequence>.png in the current folder)")
    parser.add_argument("--seed", type=seed, default=0, help="synthetic seed when --root is not given")
    parser.add_argument("--scans", type=int, default=3, help="number of scans and maps shown (default 3)")
    parser.add_argument("--frames", type=int, nargs="+", metavar="F", default=None,
                        help="frames to show (default: --scans frames evenly spread over the sequence)")
    parser.add_argument("--density", action="store_true",
                        help="add a row of BEV-density views (BEVPlace's encoding of the scans)")
    parser.add_argument("--bev-root", metavar="DIR", default=None,
                        help="BEVPlace-layout image folder of the same sequence: add its images of the "
                             "shown frames (implies --density) and compare them with the density views")
    parser.add_argument("--beside-synth", action="store_true",
                        help="add the same frames of the synthetic default (--seed) beside, same rows")


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


def top_views(seq, frames: np.ndarray, config=None) -> np.ndarray:
    """Top views (F, H, W) of `frames` (default: the paper's occupancy maps, `MapConfig()`)."""
    from safl_bench.views.mapbuild import build_views
    from safl_bench.views.mapconfig import MapConfig

    views = build_views(seq, config or MapConfig(), frames, {"clean": None}, ["topview"], progress=False)
    return np.asarray(views["clean", "topview"])


def agreement(ours: np.ndarray, theirs: np.ndarray) -> tuple[float, float]:
    """(IoU of the non-zero pixels, share of equal 8-bit values) of two [0, 1] images."""
    a = np.rint(np.asarray(ours) * 255).astype(np.int32)
    b = np.rint(np.asarray(theirs) * 255).astype(np.int32)
    union = int(((a > 0) | (b > 0)).sum())
    iou = float(((a > 0) & (b > 0)).sum() / union) if union else 1.0
    return iou, float((a == b).mean())


def _synth_sequence(name: str, seed: int):
    from safl_bench import synth
    from safl_bench.sources.kitti import open_sequence

    if name not in synth.KNOWN_SEQUENCES:
        raise DataError(f"unknown synthetic sequence {name!r}; known: {' '.join(synth.KNOWN_SEQUENCES)}")
    root = synth.default_root(seed)
    synth.ensure(root, [name], seed=seed)
    return root, open_sequence(root, name)


def main(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from safl_bench.sources.kitti import open_sequence
    from safl_bench.views.mapconfig import bev_density_config

    name = str(args.sequence)
    if args.scans < 1 or args.scans > 8:
        raise DataError(f"--scans must be between 1 and 8, got {args.scans}")
    out = Path(args.out).expanduser() if args.out else Path(f"show-{name}.png")
    if out.is_dir():
        raise DataError(f"--out {out} is a directory; give a .png file name")
    if args.root is None:
        if args.beside_synth:
            raise DataError("--beside-synth compares a --kitti-root sequence with the synthetic default; give --kitti-root")
        root, seq = _synth_sequence(name, args.seed)
    else:
        root = Path(args.root).expanduser()
        seq = open_sequence(root, name)
    if args.frames is not None:
        frames = np.asarray(args.frames, dtype=np.int64)
        if len(frames) > 8 or frames.min() < 0 or frames.max() >= len(seq):
            raise DataError(f"--frames: up to 8 frames in 0..{len(seq) - 1}, got {' '.join(map(str, args.frames))}")
    else:
        n = args.scans
        frames = np.linspace(0, len(seq) - 1, n + 2).round().astype(np.int64)[1:-1]
    bev_seq = None
    if args.bev_root is not None:
        from safl_bench.sources import bev_source

        bev = bev_source(args.bev_root)
        bev_seq = bev.sequence(name)
        if len(bev_seq) <= frames.max():
            raise DataError(f"{bev_seq.folder}: {len(bev_seq)} images, no image of frame {frames.max()}")
    density = args.density or bev_seq is not None
    blocks = [(f"{root} {name}", seq, frames, bev_seq)]
    if args.beside_synth:
        _, synth_seq = _synth_sequence("00", args.seed)
        blocks.append(("synthetic default 00", synth_seq, np.minimum(frames, len(synth_seq) - 1), None))
    rows = 2 + int(density) + int(bev_seq is not None)
    cols = sum(len(b[2]) for b in blocks)

    fig = plt.figure(figsize=(4.2 * (cols + 2), 4.2 * rows))
    grid = fig.add_gridspec(rows, cols + 2)
    draw_route(fig.add_subplot(grid[:, :2]), seq)
    route_ax = fig.axes[0]
    xy = seq.positions
    for i in frames:
        route_ax.annotate(f"#{i}", xy[i], fontsize=8, xytext=(4, 4), textcoords="offset points")
    col = 2
    for label, bseq, bframes, images in blocks:
        maps = top_views(bseq, bframes)
        dens = top_views(bseq, bframes, bev_density_config()) if density else None
        for k, i in enumerate(bframes):
            pts = bseq.scan(int(i))
            draw_scan(fig.add_subplot(grid[0, col]), pts,
                      f"{label}\nscan {i}: {len(pts)} points (colour = z, forward = +x)")
            ax = fig.add_subplot(grid[1, col])
            ax.imshow(maps[k], cmap="gray", vmin=0, vmax=1)
            ax.set_title(f"paper top view at scan {i}: local map -> occupancy\n"
                         f"(64 x 64, 80 m, forward = up; non-zero {(maps[k] > 0).mean():.1%})", fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
            if dens is not None:
                ax = fig.add_subplot(grid[2, col])
                ax.imshow(dens[k], cmap="gray", vmin=0, vmax=1)
                ax.set_title(f"BEV density at scan {i} (BEVPlace's encoding,\n151 x 151, 0.4 m; "
                             f"non-zero {(dens[k] > 0).mean():.1%})", fontsize=9)
                ax.set_xticks([])
                ax.set_yticks([])
            if images is not None and dens is not None:
                from safl_bench.sources.bev import decode_image

                theirs = decode_image(images.image_files[int(i)]).astype(np.float32) / 255.0
                iou, equal = agreement(dens[k], theirs)
                ax = fig.add_subplot(grid[3, col])
                ax.imshow(theirs, cmap="gray", vmin=0, vmax=1)
                ax.set_title(f"BEVPlace's image {images.image_files[int(i)].name}\n"
                             f"vs density view: IoU {iou:.3f}, equal pixels {equal:.2%}", fontsize=9)
                ax.set_xticks([])
                ax.set_yticks([])
                print(f"frame {i}: density view vs {images.image_files[int(i)]}: IoU {iou:.4f}, "
                      f"equal pixels {equal:.4%}")
            col += 1
    fig.suptitle(f"{root} - sequence {name}" + ("  |  beside: the synthetic default" if args.beside_synth else ""),
                 fontsize=10)
    fig.tight_layout()
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=80)
    except OSError as exc:
        raise DataError(f"cannot write {out}: {exc}") from exc
    finally:
        plt.close(fig)
    print(f"wrote {out}")
    return 0
