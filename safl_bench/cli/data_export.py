"""`safl-bench data export`: a scan sequence's top views in BEVPlace's image layout.

    DIR/SEQ/imgs/NNNNNN.png   8-bit grey, one per exported frame, numbered 0, 1, 2, ... in order
    DIR/SEQ/pose.txt          the LiDAR pose of each image, 12 numbers a line (3x4, row-major)
    DIR/SEQ/times.txt         its timestamp (s)
    DIR/SEQ/frames.txt        the scan each image was rendered from (with --step > 1 they differ)

The default encoding is "bev-density" (`safl_bench.views.mapconfig.bev_density_config`), whose views
are BEVPlace's PNG values / 255, so the written images are what BEVPlace's pipeline makes of
the scans and the folder reads back through the top-view image source (`--bev-root DIR`) and
other tools for BEVPlace's layout. Other encodings are written as rint(255 * value); read them
back with `--bev-resolution` set to their pixel size. A non-empty DIR/SEQ is never overwritten
without --force; with it, only the files above are replaced.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from safl_bench.cli.options import seed
from safl_bench.errors import ConfigError, DataError
from safl_bench.views.mapconfig import ENCODINGS

if TYPE_CHECKING:
    from safl_bench.sources import DataSource
    from safl_bench.views.mapconfig import MapConfig

HELP = ("write a scan sequence's top views (default: BEVPlace's BEV-density images) in BEVPlace's "
        "layout: DIR/SEQ/imgs/NNNNNN.png, pose.txt, times.txt")
#: Frames rendered at once (bounded memory on a 4541-frame KITTI sequence).
CHUNK = 256


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `data export`."""
    parser.add_argument("--encoding", choices=ENCODINGS, default="bev-density",
                        help="top-view encoding (default: %(default)s, BEVPlace's images)")
    parser.add_argument("--sequence", default="00", help="sequence to export (default 00)")
    parser.add_argument("--out", metavar="DIR", required=True,
                        help="root to write; the sequence goes to DIR/SEQ")
    parser.add_argument("--kitti-root", metavar="DIR", default=None,
                        help="KITTI odometry root (default: the synthetic default, generated if missing)")
    parser.add_argument("--step", type=int, default=1, help="export every STEP-th frame (default 1)")
    parser.add_argument("--force", action="store_true", help="replace an earlier export in DIR/SEQ")
    parser.add_argument("--seed", type=seed, default=0, help="synthetic seed when --kitti-root is not given")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def _prepare_folder(folder: Path, force: bool) -> None:
    if folder.exists() and not folder.is_dir():
        raise DataError(f"{folder} exists and is not a directory")
    if folder.is_dir() and any(folder.iterdir()):
        if not force:
            raise DataError(f"{folder} is not empty; pass --force to replace its images, pose.txt and times.txt")
        imgs = folder / "imgs"
        if imgs.is_dir():
            for old in imgs.glob("*.png"):
                old.unlink()
        for name in ("pose.txt", "times.txt", "frames.txt"):
            (folder / name).unlink(missing_ok=True)
    (folder / "imgs").mkdir(parents=True, exist_ok=True)


def export_sequence(source: DataSource, name: str, config: MapConfig, out: Path, *, step: int = 1,
                    force: bool = False, progress: bool = True) -> Path:
    """Write sequence `name` of a scan source in BEVPlace's layout under `out/name`; returns
    that folder (module doc)."""
    from PIL import Image
    from tqdm import tqdm

    from safl_bench.views.mapbuild import select_frames
    from safl_bench.views.render import build_views as render_views

    seq = source.sequence(name)
    frames = select_frames(len(seq), step)
    folder = Path(out) / name
    _prepare_folder(folder, force)
    bar = tqdm(total=len(frames), desc=f"export {name}", unit="image", disable=not progress, leave=False)
    try:
        for lo in range(0, len(frames), CHUNK):
            chunk = frames[lo:lo + CHUNK]
            views = render_views(source, name, config, chunk, {"clean": None}, ["topview"], progress=False)
            images = np.rint(np.asarray(views["clean", "topview"]) * 255.0).clip(0, 255).astype(np.uint8)
            for k, image in enumerate(images):
                Image.fromarray(image, mode="L").save(folder / "imgs" / f"{lo + k:06d}.png")
            bar.update(len(chunk))
    finally:
        bar.close()
    poses = np.asarray(seq.poses)[frames]
    (folder / "pose.txt").write_text(
        "".join(" ".join(f"{v:.9e}" for v in p[:3].ravel()) + "\n" for p in poses))
    (folder / "times.txt").write_text("".join(f"{t:.6e}\n" for t in np.asarray(seq.times)[frames]))
    (folder / "frames.txt").write_text("".join(f"{int(f)}\n" for f in frames))
    return folder


def main(args: argparse.Namespace) -> int:
    from safl_bench.sources import resolve_source
    from safl_bench.views.mapconfig import config_for_encoding

    if args.step < 1:
        raise ConfigError(f"--step must be >= 1, got {args.step}")
    name = str(args.sequence)
    out = Path(args.out).expanduser()
    folder = out / name
    if folder.is_dir() and any(folder.iterdir()) and not args.force:  # before any data is made
        raise DataError(f"{folder} is not empty; pass --force to replace its images, pose.txt and times.txt")
    config = config_for_encoding(args.encoding)
    source = resolve_source(args.kitti_root, sequences=[name], seed=args.seed, progress=not args.quiet)
    written = export_sequence(source, name, config, out, step=args.step, force=args.force,
                              progress=not args.quiet)
    n = len(list((written / "imgs").glob("*.png")))
    how = f"--bev-root {out}" + ("" if config.encoding == "bev-density" else f" --bev-resolution {config.cell_m:g}")
    print(f"{source.label} sequence {name}: {n} {config.size}x{config.size} {config.encoding} images "
          f"({config.cell_m:g} m per pixel) in {written}; read them with {how}")
    return 0
