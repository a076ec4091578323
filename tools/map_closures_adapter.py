"""What the density-image adapter changes for MapClosures (docs/reference/map-closures.md).

    python tools/map_closures_adapter.py --kitti-root ../shared/kitti-run [--frames 10]
    python tools/map_closures_adapter.py                  # the synthetic default, frames 0-9
    python tools/map_closures_adapter.py --task SAFL/Synth00-Revisit-v4   # + a whole task

Per scan, MapClosures' own density map of the scan's points ("own") against its density map of
the adapter's points ("adapter": the scan rendered as a BEV-density image, the encoding of
BEVPlace's published KITTI images, `safl_bench.views.bevdensity`, then turned back into points
by `baselines.map_closures.density_to_points`). Printed per frame: each map's extent and
non-zero cells, the ORB features MapClosures keeps (`usable_features`), and, on the 0.5 m cells
both maps cover inside the image's 50 m square, the IoU of their non-zero cells and the
correlation of their densities. Then the answers both ways: the frames fed in order (as the
revisit protocol feeds them), every closure MapClosures reports (inliers, and the error of its
relative pose against the poses). With ``--task``: the revisit task scored both ways (points
views against BEV-density views through the adapter), Recall@1, F1max, recall at 100 %
precision, closures reported, and how many queries matched the same frame both ways.

Needs map-closures (pip install 'safl-bench[mapclosures]'). RANSAC in MapClosures is not
seeded, so inlier counts move a little between runs.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from baselines.map_closures import (
    MapClosures,
    density_to_points,
    relative_pose,
    usable_features,
)
from safl_bench.views.bevdensity import density_image
from safl_bench.views.mapconfig import config_for_encoding


def metric_cells(pipe: Any, map_id: int, points: np.ndarray, res: float) -> dict[tuple[int, int], float]:
    """{(i, j) 0.5 m cell in the ground-aligned frame: density 0..255} of MapClosures' map
    `map_id` (its grid, placed by the lower bound MapClosures computes from the points,
    DensityMap.cpp lines 52-66)."""
    grid = np.asarray(pipe.get_density_map_from_id(map_id))
    T = np.asarray(pipe.get_ground_alignment_from_id(map_id))
    cells = np.floor((points @ T[:2, :3].T + T[:2, 3]) / res).astype(int)
    lower = cells.min(axis=0)
    rows, cols = np.nonzero(grid)
    return {(int(r + lower[0]), int(c + lower[1])): float(grid[r, c]) for r, c in zip(rows, cols, strict=True)}


def compare(scans: list[np.ndarray], poses: np.ndarray, window_m: float = 25.0) -> dict[str, Any]:
    """Density maps and answers of MapClosures on `scans` (sensor frame), own vs adapter."""
    method = MapClosures()
    res = method.density_map_resolution
    config = config_for_encoding("bev-density")
    ways = {"own": [s[:, :3].astype(np.float64) for s in scans],
            "adapter": [density_to_points(density_image(s, config), config.cell_m) for s in scans]}
    pipes = {way: method.pipeline() for way in ways}
    closures: dict[str, list[dict[str, Any]]] = {way: [] for way in ways}
    cells: dict[str, list[dict[tuple[int, int], float]]] = {way: [] for way in ways}
    frames: list[dict[str, Any]] = []
    for i in range(len(scans)):
        row: dict[str, Any] = {"frame": i}
        for way, maps in ways.items():
            pipe = pipes[way]
            found = pipe.get_closures(i, maps[i])
            grid = np.asarray(pipe.get_density_map_from_id(i))
            cells[way].append(metric_cells(pipe, i, maps[i], res))
            row[way] = {"points": len(maps[i]), "cells": list(grid.shape),
                        "extent_m": [round(grid.shape[0] * res, 1), round(grid.shape[1] * res, 1)],
                        "nonzero": int(np.count_nonzero(grid)),
                        "features": usable_features(grid)}
            for c in found:
                if c.number_of_inliers <= method.inliers_threshold:
                    continue
                truth = relative_pose(np.linalg.inv(poses[i]) @ poses[c.source_id])
                est = relative_pose(c.pose)
                closures[way].append({
                    "query": i, "match": int(c.source_id), "inliers": int(c.number_of_inliers),
                    "translation_error_m": round(math.hypot(est[0] - truth[0], est[1] - truth[1]), 3),
                    "yaw_error_rad": round(abs(math.remainder(est[2] - truth[2], math.tau)), 4)})
        own, ada = cells["own"][i], cells["adapter"][i]
        half = int(window_m / res)
        keys = [(a, b) for a in range(-half, half) for b in range(-half, half)]
        o = np.array([own.get(k, 0.0) for k in keys])
        a = np.array([ada.get(k, 0.0) for k in keys])
        union = np.count_nonzero((o > 0) | (a > 0))
        row["iou_nonzero"] = round(np.count_nonzero((o > 0) & (a > 0)) / union, 3) if union else None
        row["correlation"] = (round(float(np.corrcoef(o, a)[0, 1]), 3)
                              if o.std() > 0 and a.std() > 0 else None)
        frames.append(row)
    return {"frames": frames, "closures": closures}


def task_both_ways(task_id: str, kitti_root: str | None) -> dict[str, Any]:
    """The revisit task `task_id` scored on points views and on BEV-density views through the
    adapter (`safl_bench.evaluation.cell.evaluate_method`)."""
    import dataclasses

    from safl_bench.evaluation.cell import evaluate_method
    from safl_bench.run import runner
    from safl_bench.tasks import spec
    from safl_bench.tasks.task import Task

    method = MapClosures()
    options = runner.RunOptions(results_dir=Path("."), kitti_root=kitti_root, progress=False)
    registered = spec(task_id)
    out: dict[str, Any] = {"task": task_id}
    matches = {}
    for way in ("points", "adapter"):
        run_spec = registered
        kind = "points"
        if way == "adapter":
            run_spec = dataclasses.replace(registered, map_config=config_for_encoding("bev-density"))
            kind = "topview"
        task = Task.from_spec(run_spec, kitti_root=kitti_root, progress=False)
        task.prepare([kind])
        ev = evaluate_method(method, task.queries(kind), task.database(kind),
                             task.truth_for(options.evaluation),
                             revisit=task.spec.protocol == "revisit",
                             context=task.spec.context_queries)
        m = ev.metrics["single_frame"]
        o = ev.outcomes["single_frame"]
        matches[way] = o.match
        out[way] = {"recall_at_1": round(m.recall_at_1, 4), "f1_max": round(m.f1_max, 4),
                    "recall_at_100_precision": round(m.recall_at_100, 4),
                    "reported": int(m.n_claimed), "correct": int(m.n_correct),
                    "positives": int(m.n_positive), "queries": int(m.n_queries),
                    "median_ms_per_query": round(float(np.median(ev.query_s)) * 1e3, 2)}
    both = (matches["points"] >= 0) & (matches["adapter"] >= 0)
    out["same_frame_both_ways"] = int(np.count_nonzero(both & (matches["points"] == matches["adapter"])))
    out["reported_both_ways"] = int(np.count_nonzero(both))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--kitti-root", help="a KITTI odometry root (default: the synthetic default)")
    parser.add_argument("--sequence", default="00")
    parser.add_argument("--frames", type=int, default=10, help="first N frames (default 10)")
    parser.add_argument("--task", help="also score this revisit task both ways")
    parser.add_argument("--json", help="write every figure to this file")
    args = parser.parse_args(argv)
    from safl_bench.sources import resolve_source

    source = resolve_source(args.kitti_root, sequences=[args.sequence], progress=False)
    seq = source.sequence(args.sequence)
    n = min(args.frames, len(seq))
    scans = [np.asarray(seq.scan(i)) for i in range(n)]
    result: dict[str, Any] = {"source": source.label, "sequence": args.sequence, "frames": n,
                              **compare(scans, np.asarray(seq.poses[:n]))}
    print(f"{source.label}, sequence {args.sequence}, frames 0-{n - 1}: MapClosures' density "
          "maps, own (scan points) vs adapter (BEV-density image -> points)")
    print("frame  own cells  nonzero  features | adapter cells  nonzero  features | IoU   corr")
    for f in result["frames"]:
        o, a = f["own"], f["adapter"]
        print(f"{f['frame']:5d}  {o['cells'][0]:4d}x{o['cells'][1]:<4d} {o['nonzero']:7d}  {o['features']:8d} | "
              f"{a['cells'][0]:4d}x{a['cells'][1]:<8d} {a['nonzero']:7d}  {a['features']:8d} | "
              f"{f['iou_nonzero']}  {f['correlation']}")
    for way, found in result["closures"].items():
        print(f"closures ({way}): " + (", ".join(
            f"{c['query']}->{c['match']} ({c['inliers']} inliers, {c['translation_error_m']} m, "
            f"{c['yaw_error_rad']} rad)" for c in found) or "none"))
    if args.task:
        result["task_both_ways"] = task_both_ways(args.task, args.kitti_root)
        print(json.dumps(result["task_both_ways"], indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
