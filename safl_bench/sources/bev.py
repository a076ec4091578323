"""Top-view image folders as a data source: real KITTI without its 80 GB of scans.

Layout, relative to the root (BEVPlace's published `data/KITTI/`, Luo et al., ICCV 2023):

    <seq>/imgs/NNNNNN.png   one 8-bit grey image per frame, square, any size (BEVPlace's are
                            151 x 151: a count of 0.4 m voxels per pixel, scaled to 0-255)
    <seq>/pose.txt          12 numbers a line (3x4 row-major): the LiDAR pose of each frame
    <seq>/times.txt         optional: one timestamp (s) per frame
    <seq>/kitti_poses.txt   optional, with calib.txt: KITTI's ground-truth poses of the sequence
                            (its ``poses/<seq>.txt``: camera 0, 12 numbers a line)
    <seq>/calib.txt         optional, with kitti_poses.txt: KITTI's ``calib.txt`` of the
                            sequence, with its ``Tr:`` line (LiDAR -> camera 0)

Choices, and why:
- Ground truth: when a sequence carries KITTI's poses and calibration, they WIN over
  `pose.txt`: the LiDAR poses are ``inv(Tr) P Tr`` (`safl_bench.sources.kitti`), what KITTI's
  odometry benchmark defines. BEVPlace's ``00/pose.txt`` is written with 6 decimals on frames
  3350-3849 and differs there from KITTI's ground truth by up to 1.08 m; the rest of 00, 02, 05
  and 06 equal KITTI's to 1e-14 m (/work/shared/kitti-poses). One file without the other is an
  error, not a silent fallback. Which poses a sequence used is in its `notes` (so in every
  record) and both files are part of its fingerprint.
- Positions are x and y of the LiDAR pose (columns 3 and 7 of `pose.txt`), the ground plane;
  BEVPlace's published Recall@1 is reproduced with x and y, not x and z.
- The image centre is the sensor, forward (LiDAR x) up and left (LiDAR y) left, as in this
  project's own top views; pixel (r, c) of an S x S image lies (c0 - r) * res ahead and
  (c0 - c) * res to the left of the sensor, c0 = (S - 1) / 2 (75 for BEVPlace's images).
- The resolution cannot be read from the files; it is a setting (`resolution_m`, default
  0.4 m per pixel, BEVPlace's), part of the source's fingerprint and so of every cache key.
- Without `times.txt` frames are taken as 10 Hz (KITTI's LiDAR rate); `notes` says so, and the
  runner writes it into every record of the sequence.
- The views are the images themselves, as float32 = value / 255. There are no points: methods
  that read local-map points get a one-line error. Viewpoint noise (the paper protocol) cannot
  re-render anything, so noisy queries are the images resampled to the moved viewpoint
  (`safl_bench.views.resample.move_viewpoint`: nearest neighbour, what comes from outside the image
  is empty).
- A second image folder of the same sequences (`--bev-rot-root`, $SAFL_BEV_ROT_ROOT; BEVPlace's
  `data/KITTIRot/` at commit 56483fd9, whose `data/gen_bev_images.py` yaws each scan about the
  sensor by its own random angle, 0-359 degrees, before making its image) gives the views of the
  rotated tasks (`TaskSpec.rotated`). Its frames must be the first folder's: as many images and
  the same poses, line by line, to 1e-6 (`check_same_frames`; BEVPlace's two `pose.txt` are
  byte-identical, the unrotated sensor's), else a one-line DataError naming both counts or the
  first differing line. Records of those tasks carry their own source label (`ROTATED_LABELS`),
  so the leaderboard tables them apart from the plain images.
- The decoded images of a whole sequence are cached once, uncompressed uint8, under the map
  cache (`<home>/maps/bev-<seq>/images-<key>.npy`), keyed by the size and modification time of
  every image and text file and the resolution: a cached read is one memory-mapped file.
  Rendered views are not cached (`cache_views = False`): slicing and resampling that array is
  cheaper than reading a cache file of them.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from safl_bench.common.atomic import atomic_path
from safl_bench.common.fingerprint import fingerprint
from safl_bench.errors import DataError
from safl_bench.sources.base import DataSource, file_stat
from safl_bench.sources.kitti import camera_to_lidar_poses, read_pose_lines, read_times, read_tr

DEFAULT_RESOLUTION_M = 0.4
#: Frame period assumed without `times.txt` (KITTI's LiDAR runs at 10 Hz).
ASSUMED_PERIOD_S = 0.1
BEV_ROOT_ENV = "SAFL_BEV_ROOT"
#: The second image folder of the same sequences (BEVPlace's KITTIRot): the rotated tasks' views.
BEV_ROT_ROOT_ENV = "SAFL_BEV_ROT_ROOT"
BEV_LABEL = "KITTI top-view images"
#: The source label of a rotated task's records (`TaskSpec.rotated` -> label), and so of its table.
ROTATED_LABELS = {"queries": f"{BEV_LABEL}, rotated queries (KITTIRot)",
                  "both": f"{BEV_LABEL}, rotated database and queries (KITTIRot)"}
#: Two folders' poses of one frame may differ by this much (m, and in each rotation entry).
SAME_POSE_TOLERANCE = 1e-6
IMAGE_CACHE_VERSION = 1
#: Optional files of a sequence that carry KITTI's ground truth (module docstring).
KITTI_POSES, KITTI_CALIB = "kitti_poses.txt", "calib.txt"


@dataclass(eq=False)
class BevSequence:
    """One sequence of a top-view image folder: image files, LiDAR poses, times."""

    name: str
    folder: Path
    image_files: list[Path]
    poses: np.ndarray  # (n, 4, 4) LiDAR poses
    times: np.ndarray
    times_assumed: bool
    #: the file the poses come from: pose.txt, or kitti_poses.txt (with calib.txt's Tr)
    pose_file: str = "pose.txt"
    _images: np.ndarray | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.image_files)

    @property
    def positions(self) -> np.ndarray:
        """(n, 2) x, y of each frame in the ground plane (m)."""
        return self.poses[:, :2, 3]

    @property
    def headings(self) -> np.ndarray:
        """(n,) heading (yaw about z, rad) of each frame."""
        return np.arctan2(self.poses[:, 1, 0], self.poses[:, 0, 0])


def open_bev_sequence(root: Path, name: str) -> BevSequence:
    """Open sequence `name` of a top-view image folder, checking every file cheaply (names,
    counts, poses, times; the images themselves are checked when decoded)."""
    folder = root / name
    if not folder.is_dir():
        have = sorted(p.name for p in root.iterdir() if (p / "imgs").is_dir()) if root.is_dir() else []
        raise DataError(f"{folder}: no such sequence (sequences under {root}: {', '.join(have) or 'none'})")
    imgs = folder / "imgs"
    if not imgs.is_dir():
        raise DataError(f"{imgs}: missing (one image per frame, imgs/NNNNNN.png)")
    files = sorted(imgs.glob("*.png"))
    if not files:
        raise DataError(f"{imgs}: no .png images found")
    pose_path = folder / "pose.txt"
    if not pose_path.is_file():
        raise DataError(f"{pose_path}: missing (the LiDAR pose of each frame, 12 numbers a line)")
    poses = read_pose_lines(pose_path, len(files), f"pose lines for {len(files)} images in {imgs}")
    pose_file = "pose.txt"
    kitti, calib = folder / KITTI_POSES, folder / KITTI_CALIB
    if kitti.is_file() != calib.is_file():
        present, absent = (kitti, calib) if kitti.is_file() else (calib, kitti)
        raise DataError(f"{present}: KITTI's poses need both {KITTI_POSES} and {KITTI_CALIB}; "
                        f"{absent} is missing")
    if kitti.is_file():
        camera = read_pose_lines(kitti, len(files), f"KITTI poses for {len(files)} images in {imgs}")
        poses, pose_file = camera_to_lidar_poses(camera, read_tr(calib)), KITTI_POSES
    times_path = folder / "times.txt"
    if times_path.is_file():
        times, assumed = read_times(times_path, len(files)), False
    else:
        times, assumed = np.arange(len(files), dtype=np.float64) / (1.0 / ASSUMED_PERIOD_S), True
    return BevSequence(name, folder, files, poses, times, assumed, pose_file)


def check_same_frames(first: BevSequence, second: BevSequence) -> None:
    """DataError in one line unless two image folders of one sequence show the same frames: as
    many images, and the same pose on every line (within `SAME_POSE_TOLERANCE`)."""
    a, b = first.folder / "imgs", second.folder / "imgs"
    if len(first) != len(second):
        raise DataError(f"{b} has {len(second)} images but {a} has {len(first)}: the two image "
                        f"folders of sequence {first.name} must hold the same frames")
    differs = np.abs(first.poses[:, :3, :] - second.poses[:, :3, :]).reshape(len(first), -1).max(axis=1)
    bad = np.flatnonzero(~(differs <= SAME_POSE_TOLERANCE))
    if len(bad):
        i = int(bad[0])
        raise DataError(f"{second.folder / second.pose_file} line {i + 1} differs from "
                        f"{first.folder / first.pose_file} line {i + 1} (by {differs[i]:.3g}): the two "
                        f"image folders of sequence {first.name} must hold the same frames and poses")


def decode_image(path: Path) -> np.ndarray:
    """One 8-bit grey PNG as a (S, S) uint8 array; DataError naming the file otherwise."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            if image.format != "PNG":
                raise DataError(f"{path}: not a PNG image ({image.format})")
            if image.mode != "L":
                raise DataError(f"{path}: expected an 8-bit grey image (mode L), got mode {image.mode}")
            array = np.asarray(image)
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise DataError(f"{path}: not a readable PNG image ({exc})") from None
    if array.shape[0] != array.shape[1]:
        raise DataError(f"{path}: image is {array.shape[1]}x{array.shape[0]}, not square")
    return array


def decode_images(files: Sequence[Path], progress: bool = True) -> np.ndarray:
    """Every image of a sequence as one (n, S, S) uint8 array; all must have the same size."""
    from concurrent.futures import ThreadPoolExecutor

    from tqdm import tqdm

    first = decode_image(files[0])
    out = np.empty((len(files), *first.shape), dtype=np.uint8)

    def put(i: int) -> None:  # PIL decodes without the GIL: threads use every core
        image = first if i == 0 else decode_image(files[i])
        if image.shape != first.shape:
            raise DataError(
                f"{files[i]}: image is {image.shape[1]}x{image.shape[0]}, but {files[0].name} is "
                f"{first.shape[1]}x{first.shape[0]}: all images of a sequence must have one size"
            )
        out[i] = image

    with ThreadPoolExecutor(max_workers=min(8, os.cpu_count() or 1)) as pool:
        for _ in tqdm(pool.map(put, range(len(files))), total=len(files), unit="image",
                      desc=f"images {files[0].parent.parent.name}", disable=not progress, leave=False):
            pass
    return out


@dataclass(frozen=True)
class BevSource(DataSource):
    """A folder of per-frame top-view images with poses, in BEVPlace's layout (module doc)."""

    resolution_m: float = DEFAULT_RESOLUTION_M
    kind: ClassVar[str] = "bev"
    view_kinds: ClassVar[tuple[str, ...]] = ("topview",)
    cache_views: ClassVar[bool] = False
    renders: ClassVar[str] = "images"

    def __post_init__(self) -> None:
        if not np.isfinite(self.resolution_m) or self.resolution_m <= 0:
            raise DataError(f"top-view resolution must be a number of metres per pixel > 0, got {self.resolution_m!r}")

    def _open_sequence(self, name: str) -> BevSequence:
        return open_bev_sequence(self.root, name)

    def fingerprint(self, name: str) -> str:
        seq = self.sequence(name)
        stats = [file_stat(p) for p in seq.image_files]
        return fingerprint("bev", str(self.root.resolve()), str(name), self.resolution_m,
                           [p.name for p in seq.image_files], stats,
                           file_stat(seq.folder / "pose.txt"), file_stat(seq.folder / "times.txt"),
                           *self._kitti_stats(seq))

    @staticmethod
    def _kitti_stats(seq: BevSequence) -> list[Any]:
        """The KITTI pose files' stats when the sequence uses them ([] otherwise: fingerprints
        of folders without them are as before)."""
        if seq.pose_file == "pose.txt":
            return []
        return [file_stat(seq.folder / KITTI_POSES), file_stat(seq.folder / KITTI_CALIB)]

    def notes(self, name: str) -> list[str]:
        seq = self.sequence(name)
        out = [f"top views: the images of {seq.folder / 'imgs'}, {self.resolution_m:g} m per pixel"]
        if seq.times_assumed:
            out.append(f"no {seq.folder / 'times.txt'}: frames taken as 10 Hz")
        if seq.pose_file != "pose.txt":
            out.append(f"poses: KITTI's ground truth ({seq.folder / KITTI_POSES} with "
                       f"{KITTI_CALIB}'s Tr), not pose.txt")
        return out

    def image_cache_path(self, name: str) -> Path:
        from safl_bench.paths import map_cache_dir

        key = fingerprint(IMAGE_CACHE_VERSION, self.fingerprint(name))
        return map_cache_dir() / f"bev-{name}" / f"images-{key}.npy"

    def images(self, name: str, progress: bool = True) -> np.ndarray:
        """All images of sequence `name`, (n, S, S) uint8: decoded once, then from the cache."""
        seq = self.sequence(name)
        if seq._images is None:
            path = self.image_cache_path(name)
            try:
                images = np.load(path, mmap_mode="r")
                if images.shape[0] != len(seq) or images.dtype != np.uint8:
                    raise ValueError("stale")
            except (OSError, ValueError):
                images = decode_images(seq.image_files, progress=progress)
                path.parent.mkdir(parents=True, exist_ok=True)
                with atomic_path(path) as tmp:
                    with open(tmp, "wb") as fh:
                        np.save(fh, images)
            seq._images = images
        return seq._images


def bev_source(root: str | Path, resolution_m: float = DEFAULT_RESOLUTION_M,
               label: str = BEV_LABEL) -> BevSource:
    """A top-view image folder (BEVPlace's layout); `label` names it in records and tables."""
    path = Path(root).expanduser()
    if not path.is_dir():
        raise DataError(f"top-view image root {path} does not exist or is not a directory")
    return BevSource(root=path, label=label, resolution_m=float(resolution_m))
