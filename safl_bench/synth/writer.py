"""Files in the KITTI odometry layout: scans, calibration, times, camera-frame poses, manifest.

    <root>/sequences/XX/velodyne/NNNNNN.bin   float32 x, y, z, reflectance (LiDAR frame)
    <root>/sequences/XX/calib.txt             P0..P3 (3x4) and Tr (LiDAR -> camera 0)
    <root>/sequences/XX/times.txt             one time stamp (s) per line
    <root>/poses/XX.txt                       3x4 camera-0 poses, first one identity
    <root>/sequences/XX/synth_manifest.json   how it was made; written last (not KITTI)

Every file goes through `safl_bench.common.atomic`, so an interrupted run leaves no partial file.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench.common.atomic import atomic_write_bytes, atomic_write_text

MANIFEST_NAME = "synth_manifest.json"

#: LiDAR (x forward, y left, z up) -> camera 0 (x right, y down, z forward), with a lever arm
#: of a roof-mounted sensor behind and above the camera, as on the KITTI car.
TR_LIDAR_TO_CAM = np.array(
    [
        [0.0, -1.0, 0.0, -0.01],
        [0.0, 0.0, -1.0, -0.07],
        [1.0, 0.0, 0.0, -0.28],
        [0.0, 0.0, 0.0, 1.0],
    ]
)
# Pinhole cameras of a stereo rig (focal length, principal point, baselines), not KITTI's values.
_FOCAL, _CX, _CY = 700.0, 610.0, 180.0
_BASELINES = {"P0": 0.0, "P1": -0.54, "P2": 0.06, "P3": -0.47}


def sequence_dir(root: Path, name: str) -> Path:
    return root / "sequences" / name


def scan_path(root: Path, name: str, index: int) -> Path:
    return sequence_dir(root, name) / "velodyne" / f"{index:06d}.bin"


def poses_path(root: Path, name: str) -> Path:
    return root / "poses" / f"{name}.txt"


def manifest_path(root: Path, name: str) -> Path:
    return sequence_dir(root, name) / MANIFEST_NAME


def read_manifest(root: Path, name: str) -> dict[str, Any] | None:
    """The manifest of sequence `name` under `root`, or None when it is missing or unreadable
    (the sequence then reads as incomplete)."""
    try:
        manifest = json.loads(manifest_path(root, name).read_text())
    except (OSError, ValueError):
        return None
    return manifest if isinstance(manifest, dict) else None


def _row(values: np.ndarray) -> str:
    return " ".join(f"{v:.12e}" for v in np.asarray(values, dtype=np.float64).ravel())


def calib_text() -> str:
    """calib.txt: four 3x4 projection matrices and Tr (3x4), 12 numbers a line."""
    lines = []
    for key, baseline in _BASELINES.items():
        p = np.array([[_FOCAL, 0, _CX, _FOCAL * baseline], [0, _FOCAL, _CY, 0], [0, 0, 1, 0]])
        lines.append(f"{key}: {_row(p)}")
    lines.append(f"Tr: {_row(TR_LIDAR_TO_CAM[:3])}")
    return "\n".join(lines) + "\n"


def camera_poses(lidar_poses: np.ndarray) -> np.ndarray:
    """KITTI camera-0 poses P_i = Tr @ T_lidar_i @ inv(Tr) of LiDAR poses (n,4,4)."""
    tr = TR_LIDAR_TO_CAM
    tr_inv = np.eye(4)
    tr_inv[:3, :3] = tr[:3, :3].T
    tr_inv[:3, 3] = -tr[:3, :3].T @ tr[:3, 3]
    cam = tr @ lidar_poses @ tr_inv
    return np.where(np.abs(cam) < 1e-12, 0.0, cam)  # no -0.0 / 1e-18 round-off in the files


def poses_text(lidar_poses: np.ndarray) -> str:
    cam = camera_poses(lidar_poses)
    return "".join(" ".join(f"{v:.9e}" for v in p[:3].ravel()) + "\n" for p in cam)


def times_text(times: np.ndarray) -> str:
    return "".join(f"{t:.6e}\n" for t in times)


def write_scan(root: Path, name: str, index: int, points: np.ndarray) -> int:
    """Write one scan atomically; returns its size in bytes."""
    data = np.ascontiguousarray(points, dtype=np.float32).tobytes()
    atomic_write_bytes(scan_path(root, name, index), data)
    return len(data)


def write_text_files(root: Path, name: str, lidar_poses: np.ndarray,
                     times: np.ndarray) -> dict[str, str]:
    """Write calib.txt, times.txt and poses/XX.txt; returns their sha256 by relative path."""
    files = {
        f"sequences/{name}/calib.txt": calib_text(),
        f"sequences/{name}/times.txt": times_text(times),
        f"poses/{name}.txt": poses_text(lidar_poses),
    }
    digests = {}
    for rel, text in files.items():
        atomic_write_text(root / rel, text)
        digests[rel] = hashlib.sha256(text.encode("utf-8")).hexdigest()
    return digests


def file_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()
