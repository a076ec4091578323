"""How close the synthetic default is to real KITTI, measured on BEVPlace's top-view images.

The real side is BEVPlace's published images of whole KITTI sequences (`--bev-root`); the
synthetic side is a synthetic sequence rendered in the same encoding (`bev_density_config()`,
which reproduces BEVPlace's images of real scans exactly; `safl_bench.views.bevdensity`). Both are
compared as 8-bit images (the PNG values) of every frame (`step` 1), with:

- image statistics: the share of non-zero pixels, the mean non-zero value (in [0, 1]), and the
  radial profile, the mean value of the pixels in 2 m rings around the sensor pixel; and the
  lateral occupancy, the share of non-zero pixels in 2 m bands left and right of the sensor
  (within `LATERAL_BAND_M` ahead and behind): where the roadside stands (on KITTI 00 and 02
  each side peaks 4-8 m out, at 25-34 % of the pixels, with 1-8 % within 2 m);
- difficulty curves: the median descriptor difference of two frames against the distance
  between their positions (2 m bins, 0-40 m), divided by the median difference of the frame
  pairs more than `FAR_M` (100 m) apart, so 1 means "as different as unrelated places". Every
  pair of frames counts once, whatever their time apart (KITTI drives 0.85-1.15 m per frame,
  the synthetic default 0.9: the near bins hold similar mixes of the same pass and revisits).
  Two descriptors: SAD (`baselines.sad.SAD`, its defaults, on the central 128 x 128 pixels) and
  a rotation-invariant polar descriptor, Scan Context's idea on the image: the maximum pixel
  value in each of 20 rings (to 25 m, the images' crop) x 60 sectors, compared with Scan
  Context's column-shift cosine distance (`baselines.scan_context.distance_matrix`). The same
  medians against the heading difference of pairs at the same place (within `SAME_PLACE_M`,
  3 m; 30 degree bins) show what turning does to each descriptor; and the distance curve again
  over the pairs driving the same way only (headings within `SAME_WAY_DEG`, 45 degrees), which
  leaves out the passes in the other lane a few metres over: how many of those a route holds
  moves the near bins (on data version 3, 8 % of the synthetic pairs 2-4 m apart against 0.2 %
  on KITTI 00 and 3 % on 02), and this curve shows the images without that mix;
- aliasing (`PairCurves.alias_share`): how alike distant places look, the share of the sampled
  pairs more than `FAR_M` apart whose difference is below the median difference of the pairs
  driving the same way `ALIAS_REF_M` (10-12 m) apart: a distant place that looks more like this
  one than the same street a few metres on does;
- route measures (`route_measures`, from poses and times alone): how much of a route revisits
  (a place within 5 m, more than 30 s earlier, as `synth.routes.revisit_kinds`), the loops
  that bring it back (the driving between a frame and the latest earlier pass of its place:
  shortest and median, with the time gap), the share of frames on a short lap (a loop shorter
  than `SHORT_LAP_M`, 500 m: KITTI 00, 02, 05 and 06 have none, their shortest loop is 556 m),
  and the share passing a place a third time;
- `goals`: the issue's targets (`EXCESS_GOAL`, the real non-zero range widened by `NONZERO_WIDEN`
  of each end's value, `TAU_GOAL`), each with its value and whether it is met;
- `envelope_excess`: how far, at its worst bin, a synthetic curve lies outside the min-max
  envelope of the real sequences' curves (0 when inside everywhere); bins without pairs on
  some side are skipped;
- place recognition (`place_recognition`): Recall@1 and F1max of single-frame matching (the
  descriptor's own nearest neighbour) of every top-view method on the revisit protocol, real
  (`SAFL/BEVKITTI<seq>-Revisit-v0`) against synthetic (`SAFL/Synth<seq>-Revisit-v6`, the
  method's usual input on the default, the runner's choice), read from result records or run;
  `ranking_tau` is Kendall's tau-b between the methods' orders on the synthetic task and on
  the real ones, counting as a tie every pair whose order is not resolved beyond the noise
  (`pair_orders`: the paired difference of their single-frame F1max, with its 95 % bootstrap
  interval over the queries, `safl_bench.evaluation.uncertainty`; a revisit task has one seed; an order
  is resolved only when the interval excludes 0), on either side; against the mean of the
  real tasks a pair is resolved when every real task resolves it the same way. A run picks a learned method's weights by the task's source (BiGAN and Stable-AFL
  ship weights trained on the synthetic default and others trained on real KITTI 02), so with
  the committed records their ranks compare two trainings as well as two data sets, and on 02
  the real-KITTI weights see their own training sequence; `mixed_weights` names such methods
  and the report says so. Records of one set of weights on every task (`safl-bench run
  --weights FILE`, or the cells `place_recognition` runs itself) rank the data alone.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from safl_bench.errors import DataError
from safl_bench.leaderboard.ranking import weights_label

SAD_CROP = 128
DISTANCE_EDGES_M = tuple(float(v) for v in np.arange(0.0, 42.0, 2.0))
FAR_M = 100.0
SAME_PLACE_M = 3.0
#: Pairs of the same-way distance curve: headings differ by less than this many degrees.
SAME_WAY_DEG = 45.0
HEADING_EDGES_DEG = tuple(float(v) for v in np.arange(0.0, 181.0, 30.0))
RADIAL_EDGES_M = tuple(float(v) for v in np.arange(0.0, 36.0, 2.0))
#: Lateral bins of the lateral occupancy (metres left of the sensor; negative: right), over the
#: pixels at most LATERAL_BAND_M ahead of or behind the sensor.
LATERAL_EDGES_M = tuple(float(v) for v in np.arange(-16.0, 17.0, 2.0))
LATERAL_BAND_M = 10.0
POLAR_RINGS = 20
POLAR_SECTORS = 60
POLAR_RADIUS_M = 25.0
DESCRIPTORS = ("sad", "polar")
#: Methods compared in the ranking when registered (the top-view methods). BiGAN and Stable-AFL
#: at version 1: the versions whose shipped weights were trained on the synthetic default (the
#: weights these rankings run, `place_recognition`); version 2 ships weights for real top views only.
TOPVIEW_METHODS = ("sad", "bigan@1", "stable_afl@1", "bevplace")
#: Frames whose pairs farther than FAR_M give the normaliser (evenly spaced).
FAR_SAMPLE = 500
#: Distance band, metres, of the same-way pairs whose median difference `alias_share` compares
#: the far pairs with.
ALIAS_REF_M = (10.0, 12.0)
#: A revisit after a loop shorter than this (metres of driving) is on a short lap.
SHORT_LAP_M = 500.0
#: Revisits: a place within this radius (metres) driven more than this long (s) before.
ROUTE_RADIUS_M = 5.0
ROUTE_GAP_S = 30.0
#: Query frames compared at once when collecting the near pairs.
_ROWS = 128


@dataclass
class SequenceImages:
    """One sequence's top views as 8-bit images (n, S, S) with positions (n, 2) and headings (n,)."""

    label: str
    images: np.ndarray
    positions: np.ndarray
    headings: np.ndarray
    #: timestamps (s) of the frames; with them `measure` adds the route measures
    times: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.images = as_levels(self.images)
        self.positions = np.asarray(self.positions, dtype=np.float64).reshape(-1, 2)
        self.headings = np.asarray(self.headings, dtype=np.float64).reshape(-1)
        n = len(self.images)
        if len(self.positions) != n or len(self.headings) != n:
            raise DataError(f"{self.label}: {n} images, {len(self.positions)} positions, {len(self.headings)} headings")
        if n < 2:
            raise DataError(f"{self.label}: fidelity needs at least 2 frames, got {n}")


def as_levels(images: np.ndarray) -> np.ndarray:
    """8-bit images: uint8 as they are, float views in [0, 1] as rint(255 * value)."""
    arr = np.asarray(images)
    if arr.ndim != 3 or arr.shape[1] != arr.shape[2]:
        raise DataError(f"expected square images (n, S, S), got shape {arr.shape}")
    if arr.dtype == np.uint8:
        return arr
    return np.rint(np.clip(arr.astype(np.float32), 0.0, 1.0) * 255.0).astype(np.uint8)


# -- image statistics -------------------------------------------------------------------------
@dataclass
class ImageStats:
    """Statistics of a sequence's images (values in [0, 1])."""

    nonzero_fraction: float
    mean_nonzero: float
    radial_edges_m: list[float]
    radial_profile: list[float | None]
    lateral_edges_m: list[float] = field(default_factory=list)
    #: share of non-zero pixels per lateral band (`LATERAL_EDGES_M`, positive: left)
    lateral_occupancy: list[float | None] = field(default_factory=list)


def _radius_map(size: int, resolution_m: float) -> np.ndarray:
    c0 = (size - 1) / 2.0
    r, c = np.mgrid[0:size, 0:size]
    return np.hypot(r - c0, c - c0) * resolution_m


def image_stats(images: np.ndarray, resolution_m: float = 0.4, edges_m: Sequence[float] = RADIAL_EDGES_M,
                lateral_edges_m: Sequence[float] = LATERAL_EDGES_M, band_m: float = LATERAL_BAND_M) -> ImageStats:
    """Non-zero share, mean non-zero value, radial profile (mean value per ring of `edges_m`
    around the centre pixel) and lateral occupancy (non-zero share per band of `lateral_edges_m`
    to the left of the centre pixel, rows within `band_m` of it) over all frames."""
    levels = as_levels(images)
    n, size, _ = levels.shape
    total = np.zeros((size, size), np.float64)
    nonzero = np.zeros((size, size), np.int64)
    for lo in range(0, n, 256):  # bounded temporaries on long sequences
        chunk = levels[lo:lo + 256]
        total += chunk.sum(axis=0, dtype=np.float64)
        nonzero += np.count_nonzero(chunk, axis=0)
    n_nonzero = int(nonzero.sum())
    mean_image = total / (255.0 * n)
    ring = np.digitize(_radius_map(size, resolution_m), np.asarray(edges_m)) - 1
    profile: list[float | None] = []
    for k in range(len(edges_m) - 1):
        inside = ring == k
        profile.append(float(mean_image[inside].mean()) if inside.any() else None)
    c0 = (size - 1) / 2.0
    ahead = np.abs(np.arange(size) - c0) * resolution_m <= band_m  # rows: x = (c0 - row) * cell
    left = (c0 - np.arange(size)) * resolution_m  # columns: y = (c0 - col) * cell, left positive
    share = nonzero[ahead].sum(axis=0) / float(n * int(ahead.sum()))
    band = np.digitize(left, np.asarray(lateral_edges_m)) - 1
    lateral: list[float | None] = []
    for k in range(len(lateral_edges_m) - 1):
        inside = band == k
        lateral.append(float(share[inside].mean()) if inside.any() else None)
    return ImageStats(
        nonzero_fraction=n_nonzero / float(levels.size),
        mean_nonzero=float(total.sum() / (255.0 * n_nonzero)) if n_nonzero else 0.0,
        radial_edges_m=[float(e) for e in edges_m],
        radial_profile=profile,
        lateral_edges_m=[float(e) for e in lateral_edges_m],
        lateral_occupancy=lateral,
    )


# -- descriptors and their differences --------------------------------------------------------
def central_crop(images: np.ndarray, size: int = SAD_CROP) -> np.ndarray:
    """The central size x size pixels (all of a smaller image)."""
    s = images.shape[-1]
    if s <= size:
        return images
    lo = (s - size) // 2
    return images[..., lo:lo + size, lo:lo + size]


def polar_bins(size: int, resolution_m: float, rings: int = POLAR_RINGS, sectors: int = POLAR_SECTORS,
               radius_m: float = POLAR_RADIUS_M) -> np.ndarray:
    """Bin index ring * sectors + sector of every pixel (size, size), -1 beyond `radius_m`.
    Sector 0 starts at forward (up) and sectors run counter-clockwise (towards the left), as in
    Scan Context."""
    c0 = (size - 1) / 2.0
    r, c = np.mgrid[0:size, 0:size]
    fwd, left = (c0 - r) * resolution_m, (c0 - c) * resolution_m
    dist = np.hypot(fwd, left)
    ring = np.minimum((dist / radius_m * rings).astype(np.int64), rings - 1)
    sector = np.floor((np.arctan2(left, fwd) % (2 * np.pi)) / (2 * np.pi) * sectors).astype(np.int64) % sectors
    return np.where(dist <= radius_m, ring * sectors + sector, -1)


def polar_descriptors(images: np.ndarray, resolution_m: float = 0.4, rings: int = POLAR_RINGS,
                      sectors: int = POLAR_SECTORS, radius_m: float = POLAR_RADIUS_M) -> np.ndarray:
    """(n, rings, sectors) float32: the maximum value (in [0, 1]) of the pixels in each bin."""
    levels = as_levels(images)
    n, size, _ = levels.shape
    bins = polar_bins(size, resolution_m, rings, sectors, radius_m).ravel()
    order = np.argsort(bins, kind="stable")
    order = order[bins[order] >= 0]
    sorted_bins = bins[order]
    starts = np.flatnonzero(np.r_[True, sorted_bins[1:] != sorted_bins[:-1]])
    out = np.zeros((n, rings * sectors), np.float32)
    flat = levels.reshape(n, -1)
    for lo in range(0, n, 256):
        chunk = flat[lo:lo + 256][:, order]
        out[lo:lo + 256, sorted_bins[starts]] = np.maximum.reduceat(chunk, starts, axis=1) / np.float32(255.0)
    return out.reshape(n, rings, sectors)


def describe(images: np.ndarray, descriptor: str, resolution_m: float = 0.4) -> np.ndarray:
    """Descriptors of 8-bit images: "sad" (SAD of the central 128 x 128 pixels, (n, 1024)) or
    "polar" (`polar_descriptors`, (n, 20, 60))."""
    levels = as_levels(images)
    if descriptor == "sad":
        from baselines.sad import SAD

        return SAD().describe(central_crop(levels).astype(np.float32) / np.float32(255.0))
    if descriptor == "polar":
        return polar_descriptors(levels, resolution_m)
    raise DataError(f"unknown descriptor {descriptor!r}; known: {', '.join(DESCRIPTORS)}")


def differences(queries: np.ndarray, database: np.ndarray, descriptor: str) -> np.ndarray:
    """(nq, nd) float32 differences of descriptors: SAD's mean absolute difference, or Scan
    Context's rotation-invariant column-shift cosine distance for "polar"."""
    if descriptor == "sad":
        from baselines.sad import SAD

        return np.asarray(SAD().distance(queries, database), dtype=np.float32)
    if descriptor == "polar":
        from baselines.scan_context import distance_matrix

        return np.asarray(distance_matrix(queries, database), dtype=np.float32)
    raise DataError(f"unknown descriptor {descriptor!r}; known: {', '.join(DESCRIPTORS)}")


def difference_matrix(images: np.ndarray, descriptor: str, resolution_m: float = 0.4) -> np.ndarray:
    """(n, n) float32 differences of every pair of frames under `descriptor`."""
    desc = describe(images, descriptor, resolution_m)
    return differences(desc, desc, descriptor)


# -- curves -----------------------------------------------------------------------------------
@dataclass
class Curve:
    """Median normalised difference per bin (None: no pairs), with the pair counts."""

    edges: list[float]
    values: list[float | None]
    counts: list[int]
    far_median: float | None


def _wrap_deg(a: np.ndarray) -> np.ndarray:
    return np.abs((np.degrees(a) + 180.0) % 360.0 - 180.0)


class PairCurves(NamedTuple):
    """The curves of one descriptor on one sequence (module doc)."""

    distance: Curve
    heading: Curve
    distance_same_way: Curve
    #: share of far pairs below the median same-way difference at `ALIAS_REF_M` (module doc)
    alias_share: float | None = None


def pair_curves(desc: np.ndarray, descriptor: str, positions: np.ndarray, headings: np.ndarray,
                distance_edges_m: Sequence[float] = DISTANCE_EDGES_M, far_m: float = FAR_M,
                same_place_m: float = SAME_PLACE_M,
                heading_edges_deg: Sequence[float] = HEADING_EDGES_DEG,
                far_sample: int = FAR_SAMPLE, same_way_deg: float = SAME_WAY_DEG) -> PairCurves:
    """The distance curve, the heading curve and the same-way distance curve over every pair
    of frames i < j (module doc); all three share the normaliser.

    Only the pairs the curves need are compared: those within the last distance edge (every
    one of them), and for the normaliser the pairs farther than `far_m` among `far_sample`
    evenly spaced frames (all frames when there are no more: exact on short sequences; on
    KITTI 00 500 of 4541 frames, 58k of its 8.7M far pairs)."""
    d_edges = np.asarray(distance_edges_m, dtype=np.float64)
    h_edges = np.asarray(heading_edges_deg, dtype=np.float64)
    pos = np.asarray(positions, dtype=np.float64)
    head = np.asarray(headings, dtype=np.float64)
    n = len(pos)
    reach = max(float(d_edges[-1]), same_place_m)
    near: list[list[np.ndarray]] = [[] for _ in range(len(d_edges) - 1)]
    near_same_way: list[list[np.ndarray]] = [[] for _ in range(len(d_edges) - 1)]
    turn: list[list[np.ndarray]] = [[] for _ in range(len(h_edges) - 1)]
    for lo in range(0, n, _ROWS):
        hi = min(lo + _ROWS, n)
        dist = np.hypot(pos[lo:hi, None, 0] - pos[None, :, 0], pos[lo:hi, None, 1] - pos[None, :, 1])
        upper = np.arange(n)[None, :] > np.arange(lo, hi)[:, None]
        wanted = upper & (dist <= reach)
        cols = np.flatnonzero(wanted.any(axis=0))
        if cols.size == 0:
            continue
        rows = np.flatnonzero(wanted.any(axis=1))
        block = differences(desc[lo + rows], desc[cols], descriptor)
        dist, upper = dist[np.ix_(rows, cols)], upper[np.ix_(rows, cols)]
        k = np.digitize(dist, d_edges) - 1
        ok = upper & (k >= 0) & (k < len(d_edges) - 1)
        dh = _wrap_deg(head[lo + rows][:, None] - head[cols][None, :])
        same_way = ok & (dh < same_way_deg)
        for b in np.unique(k[ok]):
            near[b].append(block[ok & (k == b)])
            near_same_way[b].append(block[same_way & (k == b)])
        same = upper & (dist <= same_place_m)
        if same.any():
            kh = np.clip(np.digitize(dh, h_edges) - 1, 0, len(h_edges) - 2)
            for b in np.unique(kh[same]):
                turn[b].append(block[same & (kh == b)])
    sample = np.unique(np.linspace(0, n - 1, min(n, far_sample)).round().astype(np.int64))
    d_far = np.hypot(*(pos[sample, None, :] - pos[None, sample, :]).transpose(2, 0, 1))
    far_pairs = np.triu(d_far > far_m, 1)
    far_vals = differences(desc[sample], desc[sample], descriptor)[far_pairs] if far_pairs.any() else np.zeros(0)
    norm = float(np.median(far_vals)) if far_vals.size else None

    def curve(edges: np.ndarray, groups: list[list[np.ndarray]]) -> Curve:
        values: list[float | None] = []
        counts: list[int] = []
        for parts in groups:
            vals = np.concatenate(parts) if parts else np.zeros(0, np.float32)
            counts.append(int(vals.size))
            values.append(float(np.median(vals)) / norm if vals.size and norm else None)
        return Curve([float(e) for e in edges], values, counts, norm)

    ref = [np.concatenate(near_same_way[b]) for b in range(len(d_edges) - 1)
           if near_same_way[b] and d_edges[b] >= ALIAS_REF_M[0] and d_edges[b + 1] <= ALIAS_REF_M[1]]
    ref_vals = np.concatenate(ref) if ref else np.zeros(0)
    alias = (float(np.mean(far_vals < np.median(ref_vals))) if ref_vals.size and far_vals.size
             else None)
    return PairCurves(curve(d_edges, near), curve(h_edges, turn), curve(d_edges, near_same_way),
                      alias)


def envelope_excess(synthetic: Curve, real: Sequence[Curve]) -> tuple[float, int | None]:
    """How far `synthetic` lies outside the min-max envelope of the `real` curves at its worst
    bin (0 inside everywhere), and that bin (None when inside or no bin is comparable)."""
    worst, where = 0.0, None
    for k, value in enumerate(synthetic.values):
        others = [c.values[k] for c in real]
        if value is None or not others or any(o is None for o in others):
            continue
        lo = min(o for o in others if o is not None)
        hi = max(o for o in others if o is not None)
        excess = max(0.0, lo - value, value - hi)
        if excess > worst:
            worst, where = excess, k
    return worst, where


# -- routes -----------------------------------------------------------------------------------
@dataclass
class RouteMeasures:
    """How a route comes back to its places (module doc); loop and gap fields are None on a
    route without revisits."""

    frames: int
    length_m: float
    revisit_share: float
    short_lap_share: float
    third_pass_share: float
    loop_min_m: float | None
    loop_median_m: float | None
    gap_median_s: float | None


def route_measures(positions: np.ndarray, times: np.ndarray) -> RouteMeasures:
    """The route measures of one sequence from its positions (n, 2) and times (n,)."""
    from safl_bench.common.loops import loop_pairs

    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if len(t) != len(pos) or len(pos) < 2:
        raise DataError(f"route measures need as many times as positions (at least 2), got "
                        f"{len(t)} and {len(pos)}")
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))])
    pairs = loop_pairs(pos, t, ROUTE_RADIUS_M, ROUTE_GAP_S)
    n = len(pos)
    if not len(pairs):
        return RouteMeasures(n, float(s[-1]), 0.0, 0.0, 0.0, None, None, None)
    queries, first = np.unique(pairs[:, 0], return_index=True)
    ends = np.append(first[1:], len(pairs))
    latest = np.array([pairs[a:b, 1].max() for a, b in zip(first, ends, strict=True)])
    # earlier passes: runs of matches more than ROUTE_GAP_S apart in time
    passes = np.array([1 + int(np.sum(np.diff(np.sort(t[pairs[a:b, 1]])) > ROUTE_GAP_S))
                       for a, b in zip(first, ends, strict=True)])
    loops = s[queries] - s[latest]
    return RouteMeasures(
        frames=n, length_m=float(s[-1]), revisit_share=len(queries) / n,
        short_lap_share=float(np.sum(loops < SHORT_LAP_M)) / n,
        third_pass_share=float(np.sum(passes >= 2)) / n,
        loop_min_m=float(loops.min()), loop_median_m=float(np.median(loops)),
        gap_median_s=float(np.median(t[queries] - t[latest])),
    )


# -- one sequence, all statistics -------------------------------------------------------------
@dataclass
class SequenceFidelity:
    """Everything measured on one sequence."""

    label: str
    frames: int
    stats: ImageStats
    distance: dict[str, Curve] = field(default_factory=dict)  # per descriptor
    heading: dict[str, Curve] = field(default_factory=dict)
    distance_same_way: dict[str, Curve] = field(default_factory=dict)
    alias_share: dict[str, float | None] = field(default_factory=dict)
    route: RouteMeasures | None = None


def measure(seq: SequenceImages, resolution_m: float = 0.4,
            descriptors: Sequence[str] = DESCRIPTORS) -> SequenceFidelity:
    """Image statistics, the curves and aliasing of every descriptor, and (with times) the route
    measures of one sequence."""
    out = SequenceFidelity(seq.label, len(seq.images), image_stats(seq.images, resolution_m))
    if seq.times is not None:
        out.route = route_measures(seq.positions, seq.times)
    for name in descriptors:
        desc = describe(seq.images, name, resolution_m)
        curves = pair_curves(desc, name, seq.positions, seq.headings)
        out.distance[name], out.heading[name] = curves.distance, curves.heading
        out.distance_same_way[name] = curves.distance_same_way
        out.alias_share[name] = curves.alias_share
    return out


# -- the goals --------------------------------------------------------------------------------
#: The synthetic SAD curve may lie at most this far outside the real envelope.
EXCESS_GOAL = 0.03
#: The synthetic non-zero share must lie in [min * (1 - w), max * (1 + w)] of the real shares.
NONZERO_WIDEN = 0.10
#: Kendall's tau of the methods' F1max, synthetic against the mean of the real sequences.
TAU_GOAL = 0.8


@dataclass
class Goal:
    """One target of the fidelity issue, its measured value and whether it is met."""

    name: str
    value: float | None
    target: str
    met: bool


def goals(excess: float, nonzero_real: Sequence[float], nonzero_synthetic: float,
          tau: float | None) -> list[Goal]:
    """The three targets: curve envelope excess <= EXCESS_GOAL, the non-zero share inside the
    real range with each end moved out by NONZERO_WIDEN of its value, ranking tau >= TAU_GOAL
    (not met when there is no tau)."""
    lo, hi = min(nonzero_real), max(nonzero_real)
    lo, hi = lo * (1.0 - NONZERO_WIDEN), hi * (1.0 + NONZERO_WIDEN)
    return [
        Goal("curve_envelope_excess", excess, f"<= {EXCESS_GOAL:g}", excess <= EXCESS_GOAL + 1e-12),
        Goal("nonzero_fraction", nonzero_synthetic, f"{100 * lo:.2f}-{100 * hi:.2f} %",
             lo <= nonzero_synthetic <= hi),
        Goal("ranking_tau", tau, f">= {TAU_GOAL:g}", tau is not None and tau >= TAU_GOAL),
    ]


# -- place recognition ------------------------------------------------------------------------
@dataclass
class MethodResult:
    """Single-frame Recall@1 and F1max of one method on one task (None: not available)."""

    method: str
    task_id: str
    recall_at_1: float | None
    f1_max: float | None
    status: str  # "record", "computed", "missing" or "failed"
    note: str = ""
    #: the weights the record was made with ("file sha256[:12]"; "" for methods without weights)
    weights: str = ""
    #: the single-frame per-query outcomes, one per seed (None: the record holds none), for the
    #: paired differences of `pair_orders`; not part of the report's JSON
    outcomes: list[Any] | None = field(default=None, repr=False, compare=False)

    def to_json(self) -> dict[str, Any]:
        """The report's view of the result (everything but the per-query outcomes)."""
        return {"method": self.method, "task_id": self.task_id, "recall_at_1": self.recall_at_1,
                "f1_max": self.f1_max, "status": self.status, "note": self.note,
                "weights": self.weights}


def result_of(record: Any, status: str = "record") -> MethodResult:
    """A record's single-frame Recall@1 and F1max, with the weights it was made with."""
    from safl_bench.results.records import seed_outcomes

    metrics = record.results["single_frame"].metrics
    return MethodResult(record.method.name, record.task.id, metrics.recall_at_1, metrics.f1_max, status,
                        weights=weights_label(record.method.params),
                        outcomes=seed_outcomes([record], "single_frame"))


def mixed_weights(results: dict[str, dict[str, MethodResult]]) -> dict[str, dict[str, str]]:
    """{method: {task: weights}} for the methods whose results on the tasks were made with more
    than one set of weights (e.g. the synthetic weights on the synthetic task and the real-KITTI
    ones on real tasks): their rank then compares trainings as well as data."""
    out = {}
    for m, per in results.items():
        used = {t: r.weights for t, r in per.items() if r.f1_max is not None}
        if len(set(used.values())) > 1:
            out[m] = used
    return out


@dataclass(frozen=True)
class PairOrder:
    """Two methods on one task: `first` minus `second` in single-frame F1max, with its 95 %
    interval (None: no per-query outcomes to pair, or not scored on the same queries), and the
    order that survives the noise: 1 (first better), -1 (second better) or 0 (tied)."""

    first: str
    second: str
    task_id: str
    difference: Any  # uncertainty.Interval | None
    order: int

    @property
    def verdict(self) -> str:
        if self.order == 0:
            return "tied"
        better, worse = (self.first, self.second) if self.order > 0 else (self.second, self.first)
        return f"{better} > {worse} resolved"


def pair_orders(results: dict[str, dict[str, MethodResult]], task: str) -> list[PairOrder]:
    """Every pair of the methods with a value on `task` (names sorted, first < second), ordered
    only when the paired difference's 95 % interval excludes 0 (module docstring)."""
    from safl_bench.evaluation.uncertainty import sample

    have = sorted(m for m in results if (r := results[m].get(task)) is not None
                  and r.f1_max is not None)
    samples = {}
    for m in have:
        outcomes = results[m][task].outcomes
        samples[m] = None if not outcomes else sample(outcomes)
    out = []
    for i, a in enumerate(have):
        for b in have[i + 1:]:
            sa, sb = samples[a], samples[b]
            diff = None
            if sa is not None and sb is not None:
                try:
                    diff = sa.minus(sb)["f1_max"]
                except DataError:  # other queries (or seeds) on the two sides: nothing to pair
                    diff = None
            order = 0
            if diff is not None and diff.excludes_zero():
                order = 1 if diff.mean > 0 else -1
            out.append(PairOrder(a, b, task, diff, order))
    return out


def _tau_b(x: Sequence[int], y: Sequence[int]) -> float | None:
    """Kendall's tau-b of two sets of pair orders (+1, -1, 0 = tied) over the same pairs:
    (concordant - discordant) / sqrt(pairs untied in x * pairs untied in y); None when either
    side ties every pair (the order is then undefined)."""
    nx = sum(1 for v in x if v)
    ny = sum(1 for v in y if v)
    if nx == 0 or ny == 0:
        return None
    return float(sum(a * b for a, b in zip(x, y, strict=True)) / math.sqrt(nx * ny))


def ranking_tau(results: dict[str, dict[str, MethodResult]], synthetic: str,
                real: Sequence[str]) -> dict[str, float | None]:
    """Kendall's tau-b of the methods' orders beyond the noise (`pair_orders`), synthetic
    against each real task and against the real tasks together ("mean": a pair is ordered when
    every real task orders it the same way, else tied), over the methods with a value on every
    task involved."""
    out: dict[str, float | None] = {}
    orders = {t: {(p.first, p.second): p.order for p in pair_orders(results, t)}
              for t in [synthetic, *real]}
    for task in [*real, "mean"]:
        involved = [synthetic, *(real if task == "mean" else [task])]
        pairs = sorted(set.intersection(*(set(orders[t]) for t in involved)))
        xs = [orders[synthetic][p] for p in pairs]
        ys = []
        for p in pairs:
            seen = {orders[t][p] for t in involved[1:]}
            ys.append(seen.pop() if len(seen) == 1 else 0)
        out[task] = _tau_b(xs, ys) if pairs else None
    return out


def place_recognition(
    methods: Sequence[str], synthetic_task: str, real_tasks: Sequence[str], *, results_dir: Path,
    extra_record_dirs: Sequence[Path] = (), bev_root: str | None = None, run: bool = True,
    skip_run: Sequence[str] = ("bevplace",), progress: bool = False,
) -> dict[str, dict[str, MethodResult]]:
    """{method: {task: result}} from the records under `results_dir` (and `extra_record_dirs`),
    running the missing cells with the runner (records written to `results_dir`) when `run`,
    except for the methods in `skip_run` (too slow on a CPU: BEVPlace takes about a second a
    frame here), which are only read. The cells run here use one instance of each method, with
    the weights it picks for the synthetic default, on every task (unlike `safl-bench run`, which
    picks them by each task's source): their ranks compare the data alone, and their records say
    which weights they hold."""
    from safl_bench.methods.method import make_method
    from safl_bench.results.records import load_records
    from safl_bench.run.runner import RunOptions, run_grid
    from safl_bench.tasks import spec

    tasks = [synthetic_task, *real_tasks]
    instances = {m: make_method(m) for m in methods}
    by_key: dict[tuple[str, str, str, int], Any] = {}
    for folder in [*extra_record_dirs, results_dir]:  # results_dir last: it wins
        for record in load_records(folder)[0]:
            by_key[record.key] = record

    def from_record(m: str, t: str) -> MethodResult | None:
        key = (instances[m].name, instances[m].version, t, spec(t).seed)
        record = by_key.get(key)
        if record is None or "single_frame" not in record.results:
            return None
        return result_of(record)

    out: dict[str, dict[str, MethodResult]] = {m: {} for m in methods}
    todo: dict[str, list[str]] = {}
    for m in methods:
        for t in tasks:
            got = from_record(m, t)
            if got is not None:
                out[m][t] = got
            elif run and m not in skip_run:
                todo.setdefault(m, []).append(t)
            else:
                why = "no record (not run here: about 1 s a frame on a CPU)" if m in skip_run else "no record"
                out[m][t] = MethodResult(m, t, None, None, "missing", why)
    if todo:
        options = RunOptions(results_dir=Path(results_dir), bev_root=bev_root, progress=progress)
        for m, ts in todo.items():
            for outcome in run_grid([instances[m]], ts, options, log=lambda _msg: None):
                rec = outcome.record
                if outcome.status == "failed" or rec is None:
                    out[m][outcome.task_id] = MethodResult(m, outcome.task_id, None, None, "failed", outcome.message)
                    continue
                out[m][outcome.task_id] = result_of(rec, "computed" if outcome.status == "computed" else "record")
    return out
