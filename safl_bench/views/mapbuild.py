"""One pass over a sequence: slide the local map and render every requested view per frame.

The local map at frame f holds scans f-K+1..f (K = `MapConfig.window`); only scans that some
requested frame needs are read. At each requested frame every requested condition's viewpoint
(the robot pose moved by that condition's seeded offset) is rendered, for every requested kind,
from the same map, so many conditions cost one pass over the scans.

The "bev-density" encoding (BEVPlace's images, `safl_bench.views.bevdensity`) counts raw points, not
local-map voxels: its top views are rendered from the raw points of the same window of scans
(kept as read, with their poses), each viewpoint being the current scan's pose moved by the
condition's offset; the local map is then only built when points views are requested.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence

import numpy as np
from tqdm import tqdm

from safl_bench.errors import ConfigError
from safl_bench.sources.kitti import KittiSequence
from safl_bench.views.bevdensity import density_views
from safl_bench.views.localmap import make_local_map
from safl_bench.views.mapconfig import MapConfig
from safl_bench.views.topview import encode, noisy_viewpoints, pose_viewpoint, render, view_points

KINDS = ("topview", "points")
#: Default frame step for tasks: the paper's authors' public code used every 4th frame.
DEFAULT_STEP = 4


def select_frames(n_scans: int, step: int = DEFAULT_STEP) -> np.ndarray:
    """Every `step`-th frame index of a sequence of `n_scans` scans, from 0."""
    if step < 1:
        raise ConfigError(f"frame step must be >= 1, got {step}")
    return np.arange(0, n_scans, step, dtype=np.int64)


def check_frames(frames: np.ndarray, n_scans: int, name: str) -> np.ndarray:
    """`frames` as int64 (F,), each within the sequence."""
    arr = np.asarray(frames)
    if arr.ndim != 1 or (arr.size and not np.issubdtype(arr.dtype, np.integer)):
        raise ConfigError(f"frames must be a 1-D array of integer frame indices, got {arr.dtype} {arr.shape}")
    arr = arr.astype(np.int64)
    if arr.size and (arr.min() < 0 or arr.max() >= n_scans):
        raise ConfigError(f"sequence {name} has frames 0..{n_scans - 1}; asked for {arr.min()}..{arr.max()}")
    return arr


def build_views(
    seq: KittiSequence,
    config: MapConfig,
    frames: np.ndarray,
    offsets: Mapping[str, np.ndarray | None],
    kinds: Sequence[str] = ("topview",),
    progress: bool = True,
) -> dict[tuple[str, str], np.ndarray | list[np.ndarray]]:
    """Render views of `seq` at `frames` for each named viewpoint offset set.

    `offsets` maps a label (e.g. a condition name) to (F, 3) robot-frame offsets for the F
    frames, or None for the clean viewpoint. Returns {(label, kind): views}: topview views are
    (F, size, size) float32; points views are lists of F (M_i, 3) float32 arrays.
    """
    for kind in kinds:
        if kind not in KINDS:
            raise ConfigError(f"view kind must be one of {', '.join(KINDS)}, got {kind!r}")
    frames = check_frames(frames, len(seq), seq.name)
    n_frames = len(frames)
    for label, off in offsets.items():
        if off is not None and np.shape(off) != (n_frames, 3):
            raise ConfigError(f"offsets {label!r} must be ({n_frames}, 3), got {np.shape(off)}")
    poses = seq.poses
    labels = list(offsets)
    tops = {lb: np.zeros((n_frames, config.size, config.size), np.float32) for lb in labels}
    points: dict[str, list[np.ndarray]] = {lb: [np.zeros((0, 3), np.float32)] * n_frames for lb in labels}
    out: dict[tuple[str, str], np.ndarray | list[np.ndarray]] = {}
    for lb in labels:
        for kind in kinds:
            out[lb, kind] = tops[lb] if kind == "topview" else points[lb]
    if n_frames == 0:
        return out

    # Which scans are needed, and at which of them each requested frame (position) is rendered.
    k = config.window
    needed = np.zeros(len(seq), dtype=bool)
    for f in np.unique(frames):
        needed[max(0, f - k + 1) : f + 1] = True
    at: dict[int, list[int]] = {}
    for pos, f in enumerate(frames):
        at.setdefault(int(f), []).append(pos)

    density = config.encoding == "bev-density"
    use_map = not density or "points" in kinds
    local = make_local_map(config)
    recent: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=k)  # bev-density: raw scans
    last = -2
    scans = np.flatnonzero(needed)
    for i in tqdm(scans, desc=f"maps {seq.name}", unit="scan", disable=not progress, leave=False):
        if i != last + 1 and (local.count or recent):  # a gap longer than the window: start afresh
            local = make_local_map(config)
            recent.clear()
        last = int(i)
        scan = seq.scan(int(i))
        if use_map:
            local.insert(scan, poses[i])
        if density:
            recent.append((scan[:, :3], poses[i]))
        if int(i) not in at:
            continue
        robot_z = float(poses[i][2, 3])
        if use_map:
            centres = local.occupied()
        if not density:
            xy, value = encode(centres, robot_z, config)
        base = pose_viewpoint(poses[i])
        for pos in at[int(i)]:
            moves = [offsets[lb] for lb in labels]
            vps = np.stack(
                [noisy_viewpoints(base, None if m is None else m[pos])[0] for m in moves]
            )
            if "topview" in kinds:
                if density:
                    images = density_views(
                        list(recent), poses[i], [None if m is None else m[pos] for m in moves], config
                    )
                else:
                    images = render(xy, value, vps, config)
                for j, lb in enumerate(labels):
                    tops[lb][pos] = images[j]
            if "points" in kinds:
                for j, lb in enumerate(labels):
                    points[lb][pos] = view_points(centres, vps[j], robot_z, config.extent_m / 2)
    return out
