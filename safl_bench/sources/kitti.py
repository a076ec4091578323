"""KITTI odometry scans as a data source: the layout's reader (built on pykitti) and `KittiSource`.

The same layout serves real KITTI and the synthetic default (`safl_bench.sources.synth`).

Layout, relative to the root:

    sequences/XX/velodyne/NNNNNN.bin   float32 x, y, z, reflectance per point
    sequences/XX/calib.txt             P0..P3 and Tr (LiDAR -> camera 0), 12 numbers each
    sequences/XX/times.txt             one timestamp (s) per scan
    poses/XX.txt                       camera-0 poses, 12 numbers (3x4, row-major) per scan

Poses are converted to the LiDAR frame of scan 0 (x forward, y left, z up):
T_lidar_i = inv(Tr) @ P_i @ Tr. Everything that can be checked cheaply (file presence, counts,
file sizes, the text files' values) is checked when the sequence is opened; a scan's values are
checked when it is read. Every problem is a `DataError` naming the file.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np

from safl_bench.common.fingerprint import fingerprint
from safl_bench.errors import DataError
from safl_bench.sources.base import DataSource, file_stat

POINT_BYTES = 16  # float32 x, y, z, reflectance


def read_lines(path: Path) -> list[str]:
    try:
        text = path.read_text()
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a text file ({exc.reason})") from exc
    return [line for line in text.splitlines() if line.strip()]


def parse_numbers(path: Path, lineno: int, text: str, count: int | None) -> np.ndarray:
    try:
        values = np.array([float(tok) for tok in text.split()], dtype=np.float64)
    except ValueError as exc:
        raise DataError(f"{path} line {lineno}: not a list of numbers: {text.strip()[:60]!r}") from exc
    if count is not None and values.size != count:
        raise DataError(f"{path} line {lineno}: expected {count} numbers, got {values.size}")
    if not np.all(np.isfinite(values)):
        raise DataError(f"{path} line {lineno}: contains NaN or inf")
    return values


def read_tr(calib_path: Path) -> np.ndarray:
    """The 4x4 LiDAR -> camera-0 transform `Tr` from a KITTI `calib.txt`."""
    if not calib_path.is_file():
        raise DataError(f"{calib_path}: calibration file is missing (it must hold Tr)")
    for lineno, line in enumerate(read_lines(calib_path), start=1):
        key, sep, value = line.partition(":")
        if not sep:
            raise DataError(f"{calib_path} line {lineno}: expected 'KEY: numbers'")
        if key.strip() == "Tr":
            tr = np.eye(4)
            tr[:3, :] = parse_numbers(calib_path, lineno, value, 12).reshape(3, 4)
            if abs(np.linalg.det(tr[:3, :3])) < 1e-6:
                raise DataError(f"{calib_path}: Tr is not a rigid transform (singular rotation)")
            return tr
    raise DataError(f"{calib_path}: no 'Tr:' line (the LiDAR-to-camera transform)")


def read_times(path: Path, n: int) -> np.ndarray:
    """Timestamps (s) from `times.txt`, one per scan."""
    if not path.is_file():
        raise DataError(f"{path}: timestamps file is missing")
    lines = read_lines(path)
    if len(lines) != n:
        raise DataError(f"{path}: {len(lines)} timestamps for {n} scans")
    return np.array(
        [parse_numbers(path, i, line, 1)[0] for i, line in enumerate(lines, start=1)]
    )


def read_camera_poses(path: Path, n: int) -> np.ndarray:
    """Camera-0 poses (n, 4, 4) from `poses/XX.txt`, validated line by line."""
    return read_pose_lines(path, n, f"poses for {n} scans (one pose per scan needed)")


def read_pose_lines(path: Path, n: int, mismatch: str) -> np.ndarray:
    """n poses (n, 4, 4) of 12 numbers a line (3x4 row-major), validated line by line; another
    number of lines is a DataError "<path>: <count> <mismatch>"."""
    lines = read_lines(path)
    if len(lines) != n:
        raise DataError(f"{path}: {len(lines)} {mismatch}")
    poses = np.tile(np.eye(4), (n, 1, 1))
    for i, line in enumerate(lines):
        poses[i, :3, :] = parse_numbers(path, i + 1, line, 12).reshape(3, 4)
    return poses


def camera_to_lidar_poses(camera_poses: np.ndarray, tr: np.ndarray) -> np.ndarray:
    """T_lidar_i = inv(Tr) @ P_i @ Tr for every camera pose P_i (n, 4, 4)."""
    return np.linalg.inv(tr) @ camera_poses @ tr


def available_sequences(root: Path) -> list[str]:
    """Names of the sequence directories under `root/sequences` (sorted)."""
    seq_dir = root / "sequences"
    if not seq_dir.is_dir():
        return []
    return sorted(p.name for p in seq_dir.iterdir() if p.is_dir())


@dataclass
class KittiSequence:
    """One odometry sequence: scans read on demand, poses in the LiDAR frame of scan 0, times."""

    root: Path
    name: str
    velo_files: list[Path]
    times: np.ndarray
    tr: np.ndarray
    _poses: np.ndarray | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.velo_files)

    @property
    def poses(self) -> np.ndarray:
        """(n, 4, 4) float64 LiDAR poses relative to scan 0's LiDAR frame."""
        if self._poses is None:
            raise DataError(
                f"{self.root / 'poses' / (self.name + '.txt')}: missing; poses are required for "
                f"ground truth (KITTI publishes them for sequences 00-10 only)"
            )
        return self._poses

    @property
    def positions(self) -> np.ndarray:
        """(n, 2) x, y of each scan in the ground plane (m)."""
        return self.poses[:, :2, 3]

    @property
    def headings(self) -> np.ndarray:
        """(n,) heading (yaw about z, rad) of each scan."""
        p = self.poses
        return np.arctan2(p[:, 1, 0], p[:, 0, 0])

    def scan(self, i: int) -> np.ndarray:
        """Scan `i` as float32 (N, 4): x, y, z, reflectance; values checked."""
        if not 0 <= i < len(self):
            raise DataError(f"sequence {self.name}: scan index {i} out of range 0..{len(self) - 1}")
        path = self.velo_files[i]
        try:
            raw = np.fromfile(path, dtype=np.float32)
        except OSError as exc:
            raise DataError(f"{path}: cannot read ({exc})") from exc
        if raw.size == 0:
            raise DataError(f"{path}: empty scan (0 points)")
        if raw.size % 4:
            raise DataError(f"{path}: size {raw.size * 4} bytes is not a multiple of {POINT_BYTES}")
        points = raw.reshape(-1, 4)
        bad = ~np.isfinite(points).all(axis=1)
        if bad.any():
            raise DataError(f"{path}: {int(bad.sum())} of {len(points)} points are NaN or inf")
        return points


def open_sequence(root: Path | str, name: str, *, require_poses: bool = True) -> KittiSequence:
    """Open sequence `name` under a KITTI odometry `root`, checking its files cheaply.

    Without `poses/<name>.txt` this fails unless `require_poses=False`, in which case reading
    `.poses` (or positions/headings) fails with the same clear message.
    """
    import pykitti  # imports cv2; deferred so that importing this module stays cheap

    root = Path(root).expanduser()
    if not root.is_dir():
        raise DataError(f"{root}: dataset root does not exist or is not a directory")
    name = str(name)
    seq_dir = root / "sequences" / name
    if not seq_dir.is_dir():
        have = available_sequences(root)
        listing = ", ".join(have) if have else "none"
        raise DataError(f"{seq_dir}: no such sequence (sequences under {root}: {listing})")
    velo_dir = seq_dir / "velodyne"
    files = sorted(velo_dir.glob("*.bin")) if velo_dir.is_dir() else []
    if not files:
        raise DataError(f"{velo_dir}: no .bin scans found")
    for path in files:  # sizes only: a stat per file, no reading
        size = path.stat().st_size
        if size == 0:
            raise DataError(f"{path}: empty scan (0 bytes)")
        if size % POINT_BYTES:
            raise DataError(f"{path}: size {size} bytes is not a multiple of {POINT_BYTES}")
    n = len(files)
    tr = read_tr(seq_dir / "calib.txt")
    times = read_times(seq_dir / "times.txt", n)
    pose_path = root / "poses" / f"{name}.txt"
    have_poses = pose_path.is_file()
    if have_poses:
        read_camera_poses(pose_path, n)  # validates counts and values with line numbers
    elif require_poses:
        raise DataError(
            f"{pose_path}: missing; poses are required for ground truth "
            f"(KITTI publishes them for sequences 00-10 only)"
        )

    try:
        with contextlib.redirect_stdout(io.StringIO()):  # pykitti prints when poses are missing
            data = pykitti.odometry(str(root), name)
    except KeyError as exc:
        raise DataError(f"{seq_dir / 'calib.txt'}: missing {exc.args[0]} (pykitti needs P0-P3, Tr)") from exc
    except (ValueError, OSError) as exc:
        raise DataError(f"{seq_dir}: pykitti cannot read this sequence: {exc}") from exc
    velo_files = [Path(p) for p in data.velo_files]
    if len(velo_files) != n:  # pragma: no cover - same glob; guards against a race
        raise DataError(f"{velo_dir}: scan list changed while opening")
    poses = None
    if have_poses:
        cam = np.asarray(data.poses, dtype=np.float64).reshape(n, 4, 4)
        poses = camera_to_lidar_poses(cam, np.asarray(data.calib.T_cam0_velo, dtype=np.float64))
    return KittiSequence(root=root, name=name, velo_files=velo_files, times=times, tr=tr, _poses=poses)


@dataclass(frozen=True)
class KittiSource(DataSource):
    """A KITTI odometry root (or any directory in its layout): scans, poses, calibration, times.

    Its fingerprint covers the root path, the sizes and modification times of poses/calib/times
    and the number of scans; views are rendered from sliding local maps of the scans
    (`safl_bench.views.mapbuild`, through `safl_bench.views.render`)."""

    kind: ClassVar[str] = "kitti"

    def _open_sequence(self, name: str) -> KittiSequence:
        return open_sequence(self.root, name)

    def file_stats(self, name: str) -> dict[str, object]:
        """Sizes and mtimes of the sequence's text files and its scan count (no reading)."""
        seq_dir = self.root / "sequences" / name
        velo = seq_dir / "velodyne"
        return {
            "poses": file_stat(self.root / "poses" / f"{name}.txt"),
            "calib": file_stat(seq_dir / "calib.txt"),
            "times": file_stat(seq_dir / "times.txt"),
            "scans": sum(1 for _ in velo.glob("*.bin")) if velo.is_dir() else 0,
        }

    def fingerprint(self, name: str) -> str:
        name = str(name)
        return fingerprint("kitti", str(self.root.resolve()), name, self.file_stats(name))


def kitti_source(root: str | Path) -> KittiSource:
    """A KITTI odometry root (or any directory in its layout)."""
    path = Path(root).expanduser()
    if not path.is_dir():
        raise DataError(f"KITTI root {path} does not exist or is not a directory")
    return KittiSource(root=path, label="KITTI")
