"""Shared fixtures: a tiny dataset in the KITTI odometry layout, made here (never real KITTI).

The scene is a flat ground grid with two walls and a box beside a straight-then-turning road; the
robot's LiDAR poses are known, the camera poses are written with KITTI's Tr, as KITTI does.
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

SENSOR_HEIGHT = 1.73
# KITTI's Tr (LiDAR -> camera 0) of sequences 00-02 and rectified projection matrices.
TR = np.array([
    [4.276802385584e-04, -9.999672484946e-01, -8.084491683471e-03, -1.198459927713e-02],
    [-7.210626507497e-03, 8.081198471645e-03, -9.999413164504e-01, -5.403984729748e-02],
    [9.999738645903e-01, 4.859485810390e-04, -7.206933692422e-03, -2.921968648686e-01],
    [0.0, 0.0, 0.0, 1.0],
])
P = {
    "P0": [718.856, 0, 607.1928, 0, 0, 718.856, 185.2157, 0, 0, 0, 1, 0],
    "P1": [718.856, 0, 607.1928, -386.1448, 0, 718.856, 185.2157, 0, 0, 0, 1, 0],
    "P2": [718.856, 0, 607.1928, 45.38225, 0, 718.856, 185.2157, -0.1130887, 0, 0, 1, 0.003779761],
    "P3": [718.856, 0, 607.1928, -337.2877, 0, 718.856, 185.2157, 2.369057, 0, 0, 1, 0.004915215],
}


def scene_points(rng: np.random.Generator) -> np.ndarray:
    """World points (N, 3): ground at z = -SENSOR_HEIGHT, two walls and a box."""
    gx, gy = np.meshgrid(np.arange(-30, 60, 0.4), np.arange(-30, 30, 0.4))
    ground = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, -SENSOR_HEIGHT)], axis=1)
    wx, wz = np.meshgrid(np.arange(-20, 50, 0.25), np.arange(-SENSOR_HEIGHT, 2.0, 0.25))
    wall_l = np.stack([wx.ravel(), np.full(wx.size, 8.0), wz.ravel()], axis=1)
    wall_r = np.stack([wx.ravel(), np.full(wx.size, -9.0), wz.ravel()], axis=1)
    bx, by, bz = np.meshgrid(np.arange(14, 17, 0.25), np.arange(2, 4, 0.25), np.arange(-1.7, 0.0, 0.25))
    box = np.stack([bx.ravel(), by.ravel(), bz.ravel()], axis=1)
    pts = np.concatenate([ground, wall_l, wall_r, box])
    return pts + rng.normal(0.0, 0.01, pts.shape)


def lidar_poses(n: int) -> np.ndarray:
    """(n, 4, 4) LiDAR poses: forward at 1 m per scan, turning gently after the fifth."""
    poses = np.tile(np.eye(4), (n, 1, 1))
    x = y = yaw = 0.0
    for i in range(n):
        c, s = np.cos(yaw), np.sin(yaw)
        poses[i, :2, :2] = [[c, -s], [s, c]]
        poses[i, :3, 3] = [x, y, 0.02 * i]
        x, y = x + c, y + s
        yaw += 0.03 if i >= 5 else 0.0
    return poses


def write_kitti(root: Path, name: str = "00", n: int = 12, seed: int = 0, max_range: float = 40.0) -> Path:
    """Write sequence `name` (n scans) in the KITTI odometry layout under `root`; return root."""
    rng = np.random.default_rng(seed)
    world = scene_points(rng)
    poses = lidar_poses(n)
    seq = root / "sequences" / name
    (seq / "velodyne").mkdir(parents=True, exist_ok=True)
    (root / "poses").mkdir(parents=True, exist_ok=True)
    for i, pose in enumerate(poses):
        inv = np.linalg.inv(pose)
        local = world @ inv[:3, :3].T + inv[:3, 3]
        local = local[np.linalg.norm(local, axis=1) < max_range]
        refl = rng.random((len(local), 1))
        np.hstack([local, refl]).astype(np.float32).tofile(seq / "velodyne" / f"{i:06d}.bin")
    lines = [f"{k}: " + " ".join(f"{v:.12e}" for v in vals) for k, vals in P.items()]
    lines.append("Tr: " + " ".join(f"{v:.12e}" for v in TR[:3].ravel()))
    (seq / "calib.txt").write_text("\n".join(lines) + "\n")
    (seq / "times.txt").write_text("".join(f"{0.1 * i:.6e}\n" for i in range(n)))
    cam = TR @ poses @ np.linalg.inv(TR)
    (root / "poses" / f"{name}.txt").write_text(
        "".join(" ".join(f"{v:.12e}" for v in p[:3].ravel()) + "\n" for p in cam)
    )
    return root


@pytest.fixture(scope="module")
def one_torch_thread() -> Iterator[None]:
    """One torch thread for a module of network tests (`pytestmark = pytest.mark.usefixtures(
    "one_torch_thread")`): their results do not depend on it, and on a shared 2-core machine
    two threads wait on each other (OpenMP) and run erratically slowly."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def kitti_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A read-only tiny KITTI-layout root with sequence "00" (12 scans). Do not modify it."""
    return write_kitti(tmp_path_factory.mktemp("kitti"))


@pytest.fixture
def kitti_copy(kitti_root: Path, tmp_path: Path) -> Path:
    """A private copy of `kitti_root` that a test may corrupt."""
    dst = tmp_path / "kitti"
    shutil.copytree(kitti_root, dst)
    return dst


@pytest.fixture
def safl_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty $SAFL_HOME for the test (caches go there)."""
    home = tmp_path / "home"
    monkeypatch.setenv("SAFL_HOME", str(home))
    return home


def write_bev(root: Path, name: str = "00", n: int = 40, size: int = 41, times: bool = True,
              seed: int = 0) -> Path:
    """Write sequence `name` in BEVPlace's top-view image layout under `root` (`SEQ/imgs/*.png`,
    `SEQ/pose.txt`, optionally `SEQ/times.txt`): a route that drives 30 m out along x and back,
    so the second half revisits the first; each image shows a fixed pattern of "buildings" around
    the frame's position (0.4 m pixels, forward up, left left), as counts in steps of 25.5.
    Returns root."""
    from PIL import Image

    rng = np.random.default_rng(seed)
    landmarks = rng.uniform([-20, -15], [50, 15], (60, 2))
    half = n // 2
    xs = np.concatenate([np.linspace(0, 30, half), np.linspace(30, 0, n - half)])
    heading = np.where(np.arange(n) < half, 0.0, np.pi)
    seq = root / name
    (seq / "imgs").mkdir(parents=True, exist_ok=True)
    res, c0 = 0.4, (size - 1) / 2
    lines = []
    for i in range(n):
        c, s = np.cos(heading[i]), np.sin(heading[i])
        rel = (landmarks - [xs[i], 0.0]) @ np.array([[c, -s], [s, c]])  # world -> robot frame
        image = np.zeros((size, size), np.uint8)
        r = np.rint(c0 - rel[:, 0] / res).astype(int)
        col = np.rint(c0 - rel[:, 1] / res).astype(int)
        ok = (r >= 0) & (r < size) & (col >= 0) & (col < size)
        image[r[ok], col[ok]] = (np.arange(60)[ok] % 10 + 1) * 25.5
        Image.fromarray(image, mode="L").save(seq / "imgs" / f"{i:06d}.png")
        pose = np.eye(4)
        pose[:2, :2] = [[c, -s], [s, c]]
        pose[:3, 3] = [xs[i], 0.0, 0.0]
        lines.append(" ".join(f"{v:.9e}" for v in pose[:3].ravel()))
    (seq / "pose.txt").write_text("\n".join(lines) + "\n")
    if times:
        (seq / "times.txt").write_text("".join(f"{i:.6e}\n" for i in range(n)))  # 1 Hz
    return root


@pytest.fixture
def bev_root(tmp_path: Path) -> Path:
    """A private top-view image folder with sequence "00" (40 frames of 41 x 41)."""
    return write_bev(tmp_path / "bev")


@pytest.fixture(autouse=True)
def _task_warnings_anew() -> Iterator[None]:
    """Each test sees the registry's once-per-process task warnings afresh."""
    import importlib

    importlib.import_module("safl_bench.tasks.registry")._WARNED.clear()
    yield
