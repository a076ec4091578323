"""Benchmark: the synthetic LiDAR (ms per scan, points per scan) and town generation.

    python tests/bench_synth.py [--kitti-scan PATH.bin]   # prints medians (and a comparison
                                                          # with a real scan, if given)
    pytest tests/bench_synth.py --benchmark-only

The whole default dataset from nothing is timed by `time safl-bench data synth --out DIR`.
Not a timed test: the default test run skips benchmarks.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from safl_bench import synth


def _scene(frames: int = 1400):  # type: ignore[no-untyped-def]
    scene = synth.make_route("00", seed=0)
    world, lidar = synth.make_scene_world(scene)
    picks = np.linspace(0, len(scene.poses) - 1, frames).round().astype(int)
    return scene, world, lidar, picks


def describe(points: np.ndarray) -> str:
    r = np.linalg.norm(points[:, :3], axis=1)
    rh = np.histogram(r, bins=[0, 5, 10, 20, 40, 80, 121])[0] / len(points)
    zh = np.histogram(points[:, 2], bins=[-9, -1.5, -1.0, 0.0, 1.0, 3.0, 40])[0] / len(points)
    return (f"{len(points):6d} pts | range median {np.median(r):5.1f} m, hist "
            f"[0,5,10,20,40,80,121] {np.round(rh, 3)} | z hist [-1.5,-1,0,1,3] {np.round(zh, 3)} | "
            f"refl median {np.median(points[:, 3]):.2f}")


def test_scan_speed(benchmark) -> None:  # type: ignore[no-untyped-def]
    scene, world, lidar, picks = _scene(20)
    state = {"i": 0}

    def one() -> np.ndarray:
        i = picks[state["i"] % len(picks)]
        state["i"] += 1
        return lidar.scan(world, scene.poses[i], int(i), 0.0)

    pts = benchmark(one)
    assert len(pts) > 30_000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--kitti-scan", default=None, help="a real KITTI .bin to compare with")
    parser.add_argument("--scans", type=int, default=60)
    args = parser.parse_args()
    t = time.perf_counter()
    scene = synth.make_route("00", seed=0)
    t_route = time.perf_counter() - t
    t = time.perf_counter()
    world, lidar = synth.make_scene_world(scene)
    t_world = time.perf_counter() - t
    lidar.scan(world, scene.poses[0], 0, 0.0)  # compile / load the numba cache
    picks = np.linspace(0, len(scene.poses) - 1, args.scans).round().astype(int)
    times, counts, scans = [], [], []
    for i in picks:
        t = time.perf_counter()
        pts = lidar.scan(world, scene.poses[i], int(i), 0.0)
        times.append(time.perf_counter() - t)
        counts.append(len(pts))
        scans.append(pts[:: max(len(picks) // 4, 1)])
    print(f"sequence 00: route {t_route:.2f} s, town {world.shape[1]}x{world.shape[0]} cells in {t_world:.2f} s")
    print(f"scan: median {1e3 * statistics.median(times):.1f} ms, min {1e3 * min(times):.1f} ms "
          f"({len(lidar.elevations)} beams x {lidar.n_azimuth} azimuths); points per scan median "
          f"{int(statistics.median(counts))} (min {min(counts)}, max {max(counts)})")
    print(f"synthetic, {len(picks)} scans pooled:", describe(np.concatenate(scans)), "(count: pooled sample)")
    if args.kitti_scan:
        real = np.fromfile(args.kitti_scan, dtype=np.float32).reshape(-1, 4)
        print("real KITTI scan          :", describe(real))


if __name__ == "__main__":
    main()
