"""Routes through the street grid and the vehicle poses along them.

A route is a random walk over street crossings (straight on, left or right; no U-turns) that is
long enough for the sequence; on a small grid such walks come back to streets already driven,
in the same and in the opposite direction. Test sequences resample the walk until it has the
revisits their spec asks for (`REVISITS`). The vehicle keeps to the right-hand lane, rounds
corners on arcs, slows down for them, and varies its cruise speed a little.

Which way a route comes back is decided per sequence, after KITTI. Data version 3 asked
sequence 00 for both kinds ("both"): 6.2 % of its frames then revisited a place driven the other
way (seeds 0-5: 6-15 %), against 0.2 % on KITTI 00 and 1.1 % on 02 (`revisit_kinds`; BEVPlace's
poses), so the synthetic 00 put the opposite passes of KITTI 08 into the sequence that stands for
KITTI 00 and 02, and scored non-rotation-invariant methods on revisits the real sequences hardly
have. From data version 4 sequence 00 comes back the same way only ("same": 8-24 % of frames
revisit, seeds 0-5; KITTI 00 17 %, 02 6 %) and sequence 09 the opposite way ("opposite", the
part of KITTI 08), so the default still holds opposite-direction revisits, in their own
sequence. The towns are those of version 3 (the walk draws from its own generator).

Within its lane the vehicle wanders sideways (`lane_wander`), as a driver does: data version 2
drove the lane's centre line exactly, so a revisit saw the street from the very same lateral
position (median offset 0.00 m between a frame and its revisited place, against 0.14 m on
KITTI 00 and 0.79 m on 02, 90th percentiles 0.94 and 1.14 m; BEVPlace's poses, same-direction
revisits more than 30 s apart within 5 m), which favoured pixel-aligned descriptors on the
synthetic revisits: with the wander alone added to version 2's towns (seeds 0 and 1, the same
weights), single-frame revisit F1max fell 0.860 -> 0.816 and 0.754 -> 0.704 for SAD, 0.846 ->
0.827 and 0.892 -> 0.862 for Stable-AFL, 0.903 -> 0.879 and 0.923 -> 0.923 for BiGAN. The
wander is drawn from its own generator, so a seed's town and walk are those of version 2.

From data version 6 a walk obeys a loop rule (`LoopRule`, `ROUTE_RULES`): it never comes back to
a crossing after less than `MIN_LOOP_M` of driving, and drives no street a third time the same
way. Up to version 5 the walk only had to revisit, and circling one block is the easiest walk
that does: every revisit of sequence 00 came after a lap of one block (the shortest and the
median loop 322-399 m, seeds 0-5, so 8-25 % of its frames lay on such a lap; `laps` in the
fidelity report), and seed 0 drove about 1.5 laps of one block, six near-identical sides. KITTI
comes back only through other streets: its shortest loops (driving between two passes of a
place within 5 m, more than 30 s apart) are 795 m on 00, 1321 m on 02, 556 m on 05 and 927 m on
06 (ground-truth poses), and a third pass of a place is rare (1.2 % of the frames of 00, 0.3 %
of 05, none on 02 and 06). `MIN_LOOP_M` is the shortest of those loops, rounded down; it rules
out the lap of one block (280-460 m on these towns' 70-115 m blocks) and most loops around two.
`MAX_PASSES` is 02's and 06's count, which keeps a route from repeating a loop. Both were fixed
on the route statistics alone, before any method was run on the new data.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from safl_bench.common.loops import loop_pairs
from safl_bench.errors import ConfigError
from safl_bench.synth.streets import StreetGrid
from safl_bench.synth.world import LANE_OFFSET_M

_DIRS = ((1, 0), (0, 1), (-1, 0), (0, -1))  # east, north, west, south in plan grid steps
TURN_RADIUS_M = 9.0
#: The loop rule of data version 6 (module doc): the least driving, metres, between two visits of
#: a crossing, and the most times a street may be driven the same way.
MIN_LOOP_M = 550.0
MAX_PASSES = 2


@dataclass(frozen=True)
class LoopRule:
    """What a walk may not do (module doc): come back to a crossing within `min_loop_m` metres
    of driving (plan-frame street lengths between crossings), or drive a street the same way
    more than `max_passes` times."""

    min_loop_m: float = MIN_LOOP_M
    max_passes: int = MAX_PASSES


#: The route rule of each synthetic data version the generator makes (None: the walk is free).
ROUTE_RULES: dict[str, LoopRule | None] = {"5": None, "6": LoopRule()}
#: What a route must revisit (`plan_trajectory`): each kind's test on whether the walk drives some
#: street again the same way and the opposite way (`walk_revisits`).
REVISIT_TESTS: dict[str, Callable[[bool, bool], bool]] = {
    "both": lambda same, opposite: same and opposite,
    "same": lambda same, opposite: same and not opposite,
    "opposite": lambda same, opposite: opposite,
    "any": lambda same, opposite: same or opposite,
    "none": lambda same, opposite: True,
}
REVISITS = tuple(REVISIT_TESTS)
#: Lateral position in the lane (positive: right of the lane centre): on each street driven the
#: vehicle keeps to the lane centre or, with probability `WANDER_SHIFT_P`, to a line
#: `WANDER_SHIFT_M` further left (around parked cars and cyclists, another lane), plus a small
#: wander of standard deviation `WANDER_SD_M` about `WANDER_MEAN_M`; both are smoothed over
#: about `WANDER_LENGTH_M` of travel and clipped to `WANDER_RANGE_M`. The right end of the range
#: keeps the vehicle (roof 0.85 m either side of the sensor) clear of cars parked on the narrowest
#: streets (their left side 2.5 m right of the centre line, the lane centre 1.6 m); the left end
#: keeps it in its half of the road. A same-direction revisit's lateral offset on sequence 00
#: then has a median of 0.18 m and a 90th percentile of 0.87 m (seed 0), 0.22-0.85 m and
#: 0.5-1.7 m (seeds 1-4); KITTI 00: 0.14 / 0.94 m, 02: 0.79 / 1.14 m (pooled 0.20 / 1.11 m).
#: (Data version 3, whose 00 also drove streets the other way: 0.20 / 0.29 m on seed 0.)
WANDER_MEAN_M = -0.1
WANDER_SD_M = 0.12
WANDER_SHIFT_P = 0.3
WANDER_SHIFT_M = (0.4, 1.0)
WANDER_LENGTH_M = 40.0
WANDER_RANGE_M = (-1.0, 0.1)


@dataclass(frozen=True)
class Trajectory:
    """Sampled vehicle states: world xy (n,2), heading (n,), roll/pitch (n,), times (n,), and
    the height of the ground under the vehicle (n,)."""

    xy: np.ndarray
    heading: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    times: np.ndarray
    nodes: tuple[tuple[int, int], ...]  # the crossings visited, in order
    ground_z: np.ndarray  # height of the land under the vehicle (n,)

    def __len__(self) -> int:
        return len(self.times)


def random_walk(nu: int, nv: int, n_edges: int, rng: np.random.Generator,
                rule: LoopRule | None = None,
                lines: tuple[np.ndarray, np.ndarray] | None = None) -> list[tuple[int, int]]:
    """A walk over an nu x nv grid of crossings with n_edges steps and no U-turns.

    With a `rule` (which needs the street `lines`, plan u and v of the crossings) a step may only
    go where the rule allows, and a walk left with nowhere to go ends there (shorter than asked:
    `plan_trajectory` draws another when it is too short for the sequence). Without one the draws
    are those of data versions up to 5."""
    node = (int(rng.integers(0, nu)), int(rng.integers(0, nv)))
    walk = [node]
    heading = -1
    driven = 0.0
    last_seen = {node: 0.0}
    passes: dict[tuple[tuple[int, int], tuple[int, int]], int] = {}
    for _ in range(n_edges):
        options, weights = [], []
        turns = ((0, 0.5), (1, 0.25), (3, 0.25)) if heading >= 0 else tuple((t, 1.0) for t in range(4))
        for turn, w in turns:
            h = (max(heading, 0) + turn) % 4
            nxt = (node[0] + _DIRS[h][0], node[1] + _DIRS[h][1])
            if 0 <= nxt[0] < nu and 0 <= nxt[1] < nv:
                if rule is not None and not _allowed(rule, lines, node, nxt, driven, last_seen, passes):
                    continue
                options.append((h, nxt))
                weights.append(w)
        if not options and rule is not None:
            break
        if not options:  # a dead end only at a 1-wide grid: turn around
            h = (heading + 2) % 4
            options, weights = [(h, (node[0] + _DIRS[h][0], node[1] + _DIRS[h][1]))], [1.0]
        p = np.asarray(weights) / np.sum(weights)
        heading, nxt = options[int(rng.choice(len(options), p=p))]
        if rule is not None:
            driven += _street_length(lines, node, nxt)
            last_seen[nxt] = driven
            passes[(node, nxt)] = passes.get((node, nxt), 0) + 1
        node = nxt
        walk.append(node)
    return walk


def _street_length(lines: tuple[np.ndarray, np.ndarray] | None, a: tuple[int, int],
                   b: tuple[int, int]) -> float:
    """Plan length of the street between neighbouring crossings a and b."""
    if lines is None:
        raise ConfigError("a loop rule needs the street lines of the grid")
    u, v = lines
    return float(abs(u[a[0]] - u[b[0]]) + abs(v[a[1]] - v[b[1]]))


def _allowed(rule: LoopRule, lines: tuple[np.ndarray, np.ndarray] | None, node: tuple[int, int],
             nxt: tuple[int, int], driven: float, last_seen: dict[tuple[int, int], float],
             passes: dict[tuple[tuple[int, int], tuple[int, int]], int]) -> bool:
    """Whether `rule` lets a walk at `node`, `driven` metres in, go on to `nxt`."""
    if passes.get((node, nxt), 0) >= rule.max_passes:
        return False
    seen = last_seen.get(nxt)
    return seen is None or driven + _street_length(lines, node, nxt) - seen >= rule.min_loop_m


def walk_revisits(walk: list[tuple[int, int]]) -> tuple[bool, bool]:
    """Whether a walk drives some street again in the same / the opposite direction."""
    edges = list(itertools.pairwise(walk))
    seen = set()
    same = opposite = False
    for a, b in edges:
        same |= (a, b) in seen
        opposite |= (b, a) in seen
        seen.add((a, b))
    return same, opposite


def _centre_line(grid: StreetGrid, walk: list[tuple[int, int]],
                 step: float) -> tuple[np.ndarray, np.ndarray]:
    """Dense plan-frame points along the walk, corners rounded by quadratic Bezier arcs.

    Also returns, for each step of the walk, the index of the dense point where it ends.
    """
    pts = np.array([grid.node(i, j) for i, j in walk])
    out = [pts[0][None, :]]
    ends = []
    for k in range(1, len(pts)):
        a, b = pts[k - 1], pts[k]
        d_in = (b - a) / np.linalg.norm(b - a)
        start = a if k == 1 else out[-1][-1]
        if k + 1 < len(pts):
            d_out = (pts[k + 1] - b) / np.linalg.norm(pts[k + 1] - b)
            turning = abs(float(d_in @ d_out)) < 0.5
        else:
            turning = False
        end = b - d_in * TURN_RADIUS_M if turning else b
        n = max(int(np.linalg.norm(end - start) / step), 1)
        t = np.arange(1, n + 1)[:, None] / n
        out.append(start + (end - start) * t)
        ends.append(sum(len(o) for o in out) - 1)
        if turning:
            exit_pt = b + d_out * TURN_RADIUS_M
            n = max(int(1.6 * TURN_RADIUS_M / step), 2)
            t = np.arange(1, n + 1)[:, None] / n
            out.append((1 - t) ** 2 * end + 2 * (1 - t) * t * b + t**2 * exit_pt)
    return np.concatenate(out), np.asarray(ends)


def _smooth_noise(n: int, rng: np.random.Generator, corr: float, scale: float) -> np.ndarray:
    """A stationary AR(1) series with correlation `corr` between steps and std `scale`."""
    e = rng.normal(0.0, scale * np.sqrt(1 - corr**2), size=n)
    out = np.empty(n)
    acc = rng.normal(0.0, scale)
    for i in range(n):
        acc = corr * acc + e[i]
        out[i] = acc
    return out


def lane_wander(ends: np.ndarray, n: int, step: float, rng: np.random.Generator) -> np.ndarray:
    """Offsets (n,) from the lane centre at points `step` metres apart along the route, whose
    streets end at the points `ends` (module doc, `WANDER_*`). Smoothed by a Gaussian of
    `WANDER_LENGTH_M` / 2, so the path stays smooth (rough noise at 0.25 m steps would jitter the
    heading, and the speed profile reads that as sharp curves)."""
    sigma = WANDER_LENGTH_M / 2.0 / step
    half = int(np.ceil(3 * sigma))
    kernel = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma) ** 2)
    street = np.minimum(np.searchsorted(ends, np.arange(n)), len(ends) - 1)
    shifted = rng.random(len(ends)) < WANDER_SHIFT_P
    line = np.where(shifted, -rng.uniform(*WANDER_SHIFT_M, size=len(ends)), 0.0)[street]
    line = np.convolve(np.pad(line, half, mode="edge"), kernel / kernel.sum(), mode="valid")
    noise = np.convolve(rng.normal(size=n + 2 * half), kernel / np.sqrt(np.sum(kernel**2)), mode="valid")
    return np.clip(WANDER_MEAN_M + line + WANDER_SD_M * noise, *WANDER_RANGE_M)


def _drive(grid: StreetGrid, walk: list[tuple[int, int]], frames: int, cruise: float,
           rate_hz: float, rng: np.random.Generator, wander_rng: np.random.Generator):
    """Drive the walk: world path (x, y, arc length s, heading) and frame arc positions."""
    step = 0.25
    centre, ends = _centre_line(grid, walk, step=step)
    tangent = np.gradient(centre, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    offset = LANE_OFFSET_M + lane_wander(ends, len(centre), step, wander_rng)
    lane = centre + offset[:, None] * np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
    x, y = grid.warp.to_world(lane[:, 0], lane[:, 1])
    xy = np.stack([x, y], axis=1)
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    heading = np.unwrap(np.arctan2(np.gradient(y), np.gradient(x)))
    curvature = np.abs(np.gradient(heading) / np.maximum(np.gradient(s), 1e-6))

    # speed: cruise with slow variation, capped by lateral acceleration in curves, then
    # limited in acceleration (forward pass) and braking (backward pass)
    ds = np.gradient(s)
    v = cruise + _smooth_noise(len(s), rng, corr=0.999, scale=0.6)
    curv = np.convolve(curvature, np.ones(9) / 9, mode="same")
    v = np.minimum(v, np.sqrt(2.2 / np.maximum(curv, 1e-6)))
    v = np.clip(v, 3.0, 13.0)
    for i in range(1, len(v)):
        v[i] = min(v[i], np.sqrt(v[i - 1] ** 2 + 2 * 1.2 * ds[i]))
    for i in range(len(v) - 2, -1, -1):
        v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + 2 * 2.5 * ds[i]))

    dt = 1.0 / rate_hz
    pos = np.empty(frames)
    pos[0] = 0.0
    for k in range(1, frames):
        pos[k] = pos[k - 1] + float(np.interp(pos[k - 1], s, v)) * dt
    return x, y, s, heading, pos, ends


def plan_trajectory(grid: StreetGrid, frames: int, rng: np.random.Generator, *,
                    wander_rng: np.random.Generator, revisits: str = "none",
                    rate_hz: float = 10.0, rule: LoopRule | None = None) -> Trajectory:
    """Poses of `frames` scans at `rate_hz` along a random route through `grid`.

    `revisits` is "same" (drive some street again the same way and none the opposite way),
    "opposite" (drive some street again the opposite way), "both" (both kinds), "any" (one of
    the two) or "none". `wander_rng` draws the lateral wander in the lane (`lane_wander`); `rng`
    everything else. `rule` is the loop rule every walk obeys (`ROUTE_RULES`; None: none).
    """
    if revisits not in REVISITS:
        raise ConfigError(f"revisits must be one of {', '.join(map(repr, REVISITS))}, got {revisits!r}")

    def accept(w: list[tuple[int, int]]) -> bool:
        return REVISIT_TESTS[revisits](*walk_revisits(w))

    nu, nv = len(grid.u_lines), len(grid.v_lines)
    if nu < 2 or nv < 2:
        raise ConfigError("a street grid needs at least 2 streets each way")
    cruise = rng.uniform(8.5, 11.0)
    spacing = float(np.mean(np.diff(grid.u_lines)) + np.mean(np.diff(grid.v_lines))) / 2
    needed = frames / rate_hz * (cruise + 1.5) + 2 * spacing  # upper bound on the distance
    n_edges = int(np.ceil(needed / spacing)) + 1
    for _ in range(2000):
        walk = random_walk(nu, nv, n_edges, rng, rule, (grid.u_lines, grid.v_lines))
        if not accept(walk):
            continue
        x, y, s, heading, pos, ends = _drive(grid, walk, frames, cruise, rate_hz, rng, wander_rng)
        if pos[-1] > s[-1]:  # a walk the loop rule ended early (otherwise the length is an upper bound)
            continue
        driven = walk[: int(np.searchsorted(s[ends], pos[-1])) + 1]
        if accept(driven):
            break
    else:  # pragma: no cover - only on grids too small to revisit
        raise ConfigError(f"no revisiting route of {frames} frames on a {nu}x{nv} street grid")
    jitter = rng.uniform(-0.002, 0.002, size=frames)
    jitter[0] = 0.0
    times = np.arange(frames) / rate_hz + jitter
    xy = np.stack([np.interp(pos, s, x), np.interp(pos, s, y)], axis=1)
    yaw = np.interp(pos, s, heading)
    # the body follows the land: pitch from the slope ahead (nose up uphill is negative pitch
    # in R = Rz Ry Rx), roll from the slope to the left; plus the suspension's small motions
    gx, gy = grid.terrain.gradient(xy[:, 0], xy[:, 1])
    ahead = gx * np.cos(yaw) + gy * np.sin(yaw)
    left = -gx * np.sin(yaw) + gy * np.cos(yaw)
    return Trajectory(
        xy=xy,
        heading=yaw,
        roll=np.arctan(left) + np.radians(_smooth_noise(frames, rng, corr=0.97, scale=0.25)),
        pitch=-np.arctan(ahead) + np.radians(_smooth_noise(frames, rng, corr=0.97, scale=0.3)),
        times=times,
        nodes=tuple(driven),
        ground_z=grid.terrain.height(xy[:, 0], xy[:, 1]),
    )


def sensor_poses(traj: Trajectory, sensor_height: float) -> np.ndarray:
    """World poses (n,4,4) of the LiDAR (x forward, y left, z up) along a trajectory."""
    n = len(traj)
    cy, sy = np.cos(traj.heading), np.sin(traj.heading)
    cp, sp = np.cos(traj.pitch), np.sin(traj.pitch)
    cr, sr = np.cos(traj.roll), np.sin(traj.roll)
    poses = np.zeros((n, 4, 4))
    # R = Rz(yaw) @ Ry(pitch) @ Rx(roll)
    poses[:, 0, 0] = cy * cp
    poses[:, 0, 1] = cy * sp * sr - sy * cr
    poses[:, 0, 2] = cy * sp * cr + sy * sr
    poses[:, 1, 0] = sy * cp
    poses[:, 1, 1] = sy * sp * sr + cy * cr
    poses[:, 1, 2] = sy * sp * cr - cy * sr
    poses[:, 2, 0] = -sp
    poses[:, 2, 1] = cp * sr
    poses[:, 2, 2] = cp * cr
    poses[:, 0, 3] = traj.xy[:, 0]
    poses[:, 1, 3] = traj.xy[:, 1]
    poses[:, 2, 3] = sensor_height + traj.ground_z
    poses[:, 3, 3] = 1.0
    return poses


def revisit_kinds(positions: np.ndarray, headings: np.ndarray, times: np.ndarray, *,
                  radius: float = 5.0, min_gap_s: float = 30.0) -> tuple[np.ndarray, np.ndarray]:
    """Per frame, whether it revisits an older place (more than `min_gap_s` earlier, within
    `radius` m) driving the same way (heading within 45 deg) / the opposite way (beyond 135 deg).

    `radius` defaults to 5 m because opposite lanes are ~3 m apart.
    """
    pairs = loop_pairs(positions, times, radius, min_gap_s)
    same = np.zeros(len(positions), dtype=bool)
    opposite = np.zeros(len(positions), dtype=bool)
    if len(pairs):
        diff = np.abs(np.angle(np.exp(1j * (headings[pairs[:, 0]] - headings[pairs[:, 1]]))))
        same[pairs[diff < np.pi / 4, 0]] = True
        opposite[pairs[diff > 3 * np.pi / 4, 0]] = True
    return same, opposite
