"""Benchmark: frames per second of the sliding local map + top view, on real-size scans.

A frame = insert a ~120k-point scan into the sliding map (dropping the oldest scan), read the
occupied voxels near the robot and project one 64x64 top view. Scans are generated here: an
HDL-64E-like pattern (64 beams, +2..-24.8 deg, 1900 azimuth steps) in a street canyon with
walls, parked-car boxes and poles, driven through at 1 m per scan.

    OMP_NUM_THREADS=1 python tests/bench_maps.py            # prints medians for both backends
    OMP_NUM_THREADS=1 pytest tests/bench_maps.py --benchmark-only

Not a timed test: the default test run skips benchmarks.
"""

from __future__ import annotations

import statistics
import sys
import time

import numpy as np

from safl_bench.localmap import make_local_map
from safl_bench.mapconfig import MapConfig
from safl_bench.topview import encode, pose_viewpoint, render

SENSOR_HEIGHT = 1.73


def _hits(origin_x: float, rng: np.random.Generator) -> np.ndarray:
    """One scan (N, 4) float32 in the sensor frame, robot at (origin_x, 0) heading +x."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return _trace(origin_x, rng)


def _trace(origin_x: float, rng: np.random.Generator) -> np.ndarray:
    elev = np.deg2rad(np.linspace(2.0, -24.8, 64))
    az = np.linspace(-np.pi, np.pi, 1900, endpoint=False)
    e, a = np.meshgrid(elev, az, indexing="ij")
    dx, dy, dz = np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)
    rng_max = np.full(e.shape, 100.0)
    t_ground = np.where(dz < 0, SENSOR_HEIGHT / np.maximum(-dz, 1e-9), np.inf)
    # walls at y = +9 and y = -10 with 10 m gaps every 40 m (side streets)
    t_wall = np.full(e.shape, np.inf)
    for y_wall in (9.0, -10.0):
        t = np.where(dy * y_wall > 0, y_wall / np.where(dy == 0, 1e-9, dy), np.inf)
        x_hit = origin_x + t * dx
        t = np.where(np.mod(x_hit, 40.0) < 30.0, t, np.inf)
        t_wall = np.minimum(t_wall, t)
    # parked cars: boxes 4 x 2 x 1.5 m along y = 6 every 12 m (as slabs facing the road)
    x_hit = origin_x + (6.0 / np.where(dy > 0, dy, 1e-9)) * dx
    t_car = np.where(
        (dy > 0) & (np.mod(x_hit, 12.0) < 4.0), 6.0 / np.where(dy > 0, dy, 1e-9), np.inf
    )
    z_car = t_car * dz
    t_car = np.where(z_car > -SENSOR_HEIGHT + 1.5, np.inf, t_car)
    t = np.minimum(np.minimum(t_ground, t_wall), np.minimum(t_car, rng_max))
    keep = (t < 100.0) & (rng.random(t.shape) > 0.05)  # dropouts and no-return sky
    t = t[keep] + rng.normal(0.0, 0.02, keep.sum())
    pts = np.stack([t * dx[keep], t * dy[keep], t * dz[keep], rng.random(keep.sum())], axis=1)
    return pts.astype(np.float32)


def make_scans(n: int, seed: int = 0) -> tuple[list[np.ndarray], np.ndarray]:
    """n scans (~115k points each) and their poses, 1 m apart along x."""
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.arange(n, dtype=np.float64)
    return [_hits(float(i), rng) for i in range(n)], poses


def frame_times(
    backend: str, scans: list[np.ndarray], poses: np.ndarray, warmup: int = 12
) -> list[float]:
    """Seconds per frame (insert + drop + read + project one view), after `warmup` frames."""
    cfg = MapConfig(backend=backend)
    local = make_local_map(cfg)
    times = []
    for i, (scan, pose) in enumerate(zip(scans, poses, strict=True)):
        t0 = time.perf_counter()
        local.insert(scan, pose)
        centres = local.occupied()
        xy, value = encode(centres, pose[2, 3], cfg)
        render(xy, value, pose_viewpoint(pose)[None], cfg)
        if i >= warmup:
            times.append(time.perf_counter() - t0)
    return times


def test_bench_voxel_frame(benchmark) -> None:  # type: ignore[no-untyped-def]
    scans, poses = make_scans(40)
    cfg = MapConfig()
    local = make_local_map(cfg)
    for scan, pose in zip(scans[:12], poses[:12], strict=True):
        local.insert(scan, pose)
    state = {"i": 12}

    def frame() -> None:
        i = state["i"] % len(scans)
        state["i"] += 1
        pose = poses[i].copy()
        pose[0, 3] = float(state["i"])
        local.insert(scans[i], pose)
        xy, value = encode(local.occupied(), pose[2, 3], cfg)
        render(xy, value, pose_viewpoint(pose)[None], cfg)

    benchmark.pedantic(frame, rounds=30, iterations=1)


def test_bench_octomap_frame(benchmark) -> None:  # type: ignore[no-untyped-def]
    scans, poses = make_scans(24)
    times = benchmark.pedantic(lambda: frame_times("octomap", scans, poses), rounds=1, iterations=1)
    assert times


def main() -> int:
    n = 40
    scans, poses = make_scans(n)
    print(f"{n} scans, median {int(np.median([len(s) for s in scans]))} points each")
    for backend, count in (("voxel", n), ("octomap", 24)):
        times = frame_times(backend, scans[:count], poses[:count])
        med = statistics.median(times)
        print(
            f"{backend:8s} median {med * 1000:7.1f} ms/frame = {1 / med:6.1f} frames/s "
            f"(n={len(times)}, min {min(times) * 1000:.1f} ms)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
