"""MapClosures (Gupta et al., ICRA 2024; PRBonn, MIT licence) through its package `map-closures`.

A retrieval method (`safl_bench.methods.retrieval`): per map it builds a bird's-eye-view density
map (points per 0.5 m cell, min-max normalised, cut below 0.05), extracts ORB features, looks
them up in a Hamming-distance search tree (HBST) holding every earlier map's features, and
verifies each earlier map that shares more than two feature matches with a 2-D RANSAC
alignment; the confidence of a candidate is its number of inliers. Everything below was read in
the package at 2.2.0 (the Python sources of its sdist) and in PRBonn/MapClosures' C++ at commit
``1710f15`` (the newest the sdist's CMake points at that we could read: the sdist ships no C++;
its behaviour was checked against the installed 2.2.0 wheel by the tests).

Configuration (constructor defaults = the published ones, ``map_closures/config/config.py``
lines 33-36 at 2.2.0): ``density_map_resolution`` 0.5 m, ``density_threshold`` 0.05,
``hamming_distance_threshold`` 50, ``inliers_threshold`` 5. The first three go to the C++
pipeline; ``inliers_threshold`` is applied the way its own pipeline applies it
(``map_closures/pipeline.py`` line 142: a closure counts when ``number_of_inliers >
inliers_threshold``), so a candidate with 5 inliers or fewer is not reported. Fixed in the C++
(``cpp/map_closures/MapClosures.cpp`` lines 39-52): ORB with 500 features, one level, FAST
threshold 35; a map skips the 3 maps before it (``no_of_local_maps_to_skip``); a candidate needs
more than 2 descriptor matches. RANSAC (``AlignRansac2D.cpp`` lines 60-69, 92): 688 trials,
inliers within 3 cells, samples drawn from ``std::random_device``: NOT seedable, so answers can
differ between two identical runs (measured in docs/reference/map-closures.md, "Repeatability");
`deterministic` is False. So on a task where nothing is random (the revisit and BEVPlace
protocols) `safl-bench run` runs each cell `safl_bench.run.runner.REPEATS` (3) times, as seeds
0-2, and the tables read them as runs of one cell: its value is their mean, its interval covers
their spread (`safl_bench.results.records.is_repeat`); a paper-protocol cell's noise seeds are
already separate runs.

How the harness feeds it (MapClosures is online: each call adds the map to its database, and it
has no query-only call in its Python API, ``Match`` being a protected C++ method):

* revisit tasks (``same_frames``: the queries are the database frames in time order): frame i is
  map i, fed in order with ``get_closures(i, map)``: its answer can only hold earlier frames,
  as on a robot; the harness then drops those the time window forbids (``db_limit``).
* separate database and queries (paper and BEVPlace protocols): the database maps first, ids
  0..Ndb-1 (each such call also verifies against earlier database maps; that time is not a
  query's), then each query in task order with id Ndb + 3 + q, so that MapClosures' own skip of
  the 3 previous maps never hides a database map. Candidates that are earlier queries are
  dropped (they are not database frames). The search tree then also holds the earlier queries'
  features, which can change which database features a query's features meet (HBST splits its
  leaves as it grows): a query's answer may depend on the queries before it, never on a frame
  it may not match. Deterministic order, stated here.
* an empty map (no point, or an all-zero image) is never given to MapClosures (its density map
  of no point would have a negative size): its answer is "no match", recorded as such, and it
  is not added to the database.
* a map whose density map yields fewer than 3 usable features (`usable_features`: MapClosures'
  ORB settings and its self-similarity filter, replayed with this project's OpenCV on the
  density map MapClosures made) answers "no match" too: with no feature MapClosures' search
  leaves the previous query's matches in place (HBST's matchAndAdd does not clear them) and
  version 2.2.0 then reports the PREVIOUS map's closures as this one's (measured: a map of one
  point answered four closures of 101 inliers each); with fewer than 3 no candidate can have
  the more than 2 matches it needs anyway. The check runs only on maps that got closures and
  costs about a millisecond each, inside the harness's share of the time.

Inputs. ``input_kind = "points"``: the pipeline's local maps in each viewpoint's frame (synthetic
default, KITTI scans). On a source without points (top-view image folders, e.g. BEVPlace's
KITTI images) it reads the images through `density_to_points` (``reads_topview``), the adapter
that turns a density image back into points; what it changes is measured by
``tools/map_closures_adapter.py`` (docs/reference/map-closures.md).

Relative pose. MapClosures' ``closure.pose`` maps the reference (source, database) map's
points into the query (target) map's frame (``MapClosures.cpp`` lines 219-232: RANSAC fits
``T * ref ~ query`` on keypoints in cells, the translation is scaled by the resolution to
metres, then the ground alignments are undone), i.e. it is T_query^-1 T_ref; its SE(2) part
[x, y, yaw] is what `Retrieval.pose` holds, in metres and radians.
"""

from __future__ import annotations

import functools
import math
import time
from typing import Any, ClassVar

import numpy as np

from safl_bench.errors import ConfigError, DataError
from safl_bench.methods.method import Views, register_method
from safl_bench.methods.retrieval import Retrieval, RetrievalMethod

#: The one line when the package is missing.
MISSING = ("method 'map_closures' needs the package map-closures 2.2.0: "
           "pip install 'safl-bench[mapclosures]'")

#: MapClosures skips this many maps before the query (MapClosures.cpp line 40).
SKIPPED_MAPS = 3

#: Sub-pixel positions (fractions of a pixel along x and y) of the adapter's points: the
#: centres of a 4 x 4 grid, in an order that spreads the first n of them over the pixel.
_SUB = np.array([(0.125 + 0.25 * (k % 4), 0.125 + 0.25 * (k // 4))
                 for k in (0, 10, 8, 2, 5, 15, 13, 7, 1, 11, 9, 3, 4, 14, 12, 6)])


def density_to_points(image: np.ndarray, cell_m: float = 0.4, levels: int = 10) -> np.ndarray:
    """The adapter from a top-view density image to points (N, 3) float64 in the viewpoint's
    frame (x forward, y left, z = 0): each pixel of value v in [0, 1] becomes ``rint(v *
    levels)`` points spread over its cell (the first n of 16 fixed sub-pixel positions, no
    randomness). ``levels`` = 10: BEVPlace's images count up to 10 voxel centroids per pixel
    (`safl_bench.views.bevdensity.DENSITY_CAP`), so v * 10 is the count when the image's maximum
    is 10. Pixel geometry is that of `safl_bench.views.bevdensity` (step 4): with c0 = (size -
    1) / 2, row c0 - k (k > 0) spans x in [k, k + 1) cells ahead, row c0 + k spans (-(k + 1), -k]
    cells behind, row c0 spans (-1, 1) cells; columns likewise along y (left positive)."""
    img = np.asarray(image)
    if img.ndim != 2 or img.shape[0] != img.shape[1]:
        raise DataError(f"a top view must be a square (H, W) image, got shape {img.shape}")
    flat = np.rint(np.clip(img, 0.0, 1.0).ravel() * levels).astype(np.int64)
    pixels = np.flatnonzero(flat)
    if pixels.size == 0:
        return np.zeros((0, 3))
    n = flat[pixels]
    which = np.repeat(pixels, n)
    slot = (np.arange(which.size) - np.repeat(np.cumsum(n) - n, n)) % len(_SUB)
    lo, scale = _pixel_spans(img.shape[0])
    r, c = np.divmod(which, img.shape[1])
    out = np.zeros((which.size, 3))
    out[:, 0] = (lo[r] + scale[r] * _SUB[slot, 0]) * cell_m
    out[:, 1] = (lo[c] + scale[c] * _SUB[slot, 1]) * cell_m
    return out


@functools.lru_cache(maxsize=8)
def _pixel_spans(size: int) -> tuple[np.ndarray, np.ndarray]:
    """Per row (or column) index of a `size`-pixel image, the span along its axis in cells:
    ``lo + scale * u`` for u in [0, 1) (`density_to_points`' pixel geometry)."""
    k = (size - 1) / 2 - np.arange(size)
    lo = np.where(k > 0, k, np.where(k < 0, k, -1.0))
    scale = np.where(k > 0, 1.0, np.where(k < 0, -1.0, 2.0))
    return lo, scale


def usable_features(density_map: Any) -> int:
    """How many of a density map's ORB features MapClosures puts in its search tree: ORB with
    its fixed settings (MapClosures.cpp lines 44-52, 57-59), kept when the second-nearest of its
    own features is more than 35 bits away (lines 79-93); OpenCV's, not the package's copy
    (OpenCV 5 refuses MapClosures' scale factor 1.0; with one pyramid level it is never used, so
    1.2 gives the same features)."""
    import cv2

    grid = np.clip(np.asarray(density_map), 0, 255).astype(np.uint8)
    orb = cv2.ORB.create(nfeatures=500, scaleFactor=1.2, nlevels=1, edgeThreshold=31,
                         firstLevel=0, WTA_K=2, scoreType=cv2.ORB_HARRIS_SCORE, patchSize=31,
                         fastThreshold=35)
    _, desc = orb.detectAndCompute(grid, None)
    if desc is None or len(desc) < 2:
        return 0
    pairs = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(desc, desc, k=2)
    return sum(1 for p in pairs if len(p) > 1 and p[1].distance > 35)


def relative_pose(pose: Any) -> list[float]:
    """[x, y, yaw] of a 4x4 MapClosures closure pose (T_query^-1 T_ref, module docstring)."""
    T = np.asarray(pose, dtype=np.float64)
    return [float(T[0, 3]), float(T[1, 3]), math.atan2(T[1, 0], T[0, 0])]


def load_package() -> Any:
    """The `map_closures` module; ConfigError in one line naming the extra when it is absent."""
    try:
        import map_closures
        from map_closures import map_closures as api  # noqa: F401  (the compiled pipeline)
    except ImportError:
        raise ConfigError(MISSING) from None
    return map_closures


@register_method
class MapClosures(RetrievalMethod):
    """MapClosures' density maps, ORB features, HBST search and RANSAC (module docstring)."""

    name: ClassVar[str] = "map_closures"
    version: ClassVar[str] = "1"
    input_kind: ClassVar[str] = "points"
    #: On a source without points it reads top-view images through `density_to_points`.
    reads_topview: ClassVar[bool] = True
    deterministic: ClassVar[bool] = False

    def __init__(self, density_map_resolution: float = 0.5, density_threshold: float = 0.05,
                 hamming_distance_threshold: int = 50, inliers_threshold: int = 5,
                 topview_cell_m: float = 0.4) -> None:
        self.density_map_resolution = density_map_resolution
        self.density_threshold = density_threshold
        self.hamming_distance_threshold = hamming_distance_threshold
        self.inliers_threshold = inliers_threshold
        self.topview_cell_m = topview_cell_m
        if not density_map_resolution > 0 or not topview_cell_m > 0:
            raise ConfigError("density_map_resolution and topview_cell_m must be > 0 m")
        if not 0 <= density_threshold < 1:
            raise ConfigError(f"density_threshold must be in [0, 1), got {density_threshold}")
        if hamming_distance_threshold < 0 or inliers_threshold < 0:
            raise ConfigError("hamming_distance_threshold and inliers_threshold must be >= 0")
        load_package()

    def pipeline(self) -> Any:
        """A fresh MapClosures pipeline with this configuration (an empty database)."""
        load_package()
        from map_closures.config import MapClosuresConfig
        from map_closures.map_closures import MapClosures as Pipeline

        return Pipeline(MapClosuresConfig(
            density_map_resolution=self.density_map_resolution,
            density_threshold=self.density_threshold,
            hamming_distance_threshold=self.hamming_distance_threshold,
            inliers_threshold=self.inliers_threshold))

    def points(self, view: Any) -> np.ndarray:
        """A view as MapClosures reads it: (N, 3) float64 points; a 2-D array is a top view and
        goes through `density_to_points`."""
        arr = np.asarray(view)
        if arr.ndim == 2 and arr.shape[0] == arr.shape[1] and arr.shape[1] != 3:
            return density_to_points(arr, self.topview_cell_m)
        if arr.ndim != 2 or arr.shape[1] < 3:
            raise DataError(f"map_closures reads (M, 3) points or square top views, got shape "
                            f"{arr.shape}")
        return np.ascontiguousarray(arr[:, :3], dtype=np.float64)

    def _ask(self, pipe: Any, map_id: int, view: Any) -> tuple[list[Any], float]:
        """MapClosures' closures of one map (added to its database), and the seconds its call
        took (density map, ORB, search, RANSAC); none for an empty map, which is not added."""
        pts = self.points(view)
        if len(pts) == 0 or not np.isfinite(pts).all():
            if len(pts):
                raise DataError(f"map {map_id}: its points hold NaN or inf")
            return [], 0.0
        t0 = time.perf_counter()
        closures = pipe.get_closures(map_id, pts)
        seconds = time.perf_counter() - t0
        if closures and usable_features(pipe.get_density_map_from_id(map_id)) < 3:
            return [], seconds  # stale closures of the previous map (module docstring)
        return list(closures), seconds

    def own_calls(self, queries: Views, database: Views, *, same_frames: bool = False) -> float:
        """Seconds of MapClosures' own calls alone on these views, fed as `retrieve` feeds them
        (a fresh pipeline, ``get_closures`` per non-empty map), the maps converted to points
        beforehand: what `safl-bench bench retrieval` sets against the harness's time."""
        pipe = self.pipeline()
        order = list(queries) if same_frames else [*database, *queries]
        ids = (list(range(len(queries))) if same_frames else
               [*range(len(database)), *range(len(database) + SKIPPED_MAPS,
                                              len(database) + SKIPPED_MAPS + len(queries))])
        maps = [(i, p) for i, p in zip(ids, (self.points(v) for v in order), strict=True) if len(p)]
        t0 = time.perf_counter()
        for i, pts in maps:
            pipe.get_closures(i, pts)
        return time.perf_counter() - t0

    def retrieve(self, queries: Views, database: Views, *, db_limit: np.ndarray | None = None,
                 same_frames: bool = False) -> Retrieval:
        pipe = self.pipeline()
        ndb = len(database)
        if same_frames:
            if len(queries) != ndb:
                raise DataError(f"same_frames needs as many queries as database frames, got "
                                f"{len(queries)} and {ndb}")
            first = 0
        else:
            for j in range(ndb):
                self._ask(pipe, j, database[j])
            first = ndb + SKIPPED_MAPS
        index: list[list[int]] = []
        confidence: list[list[float]] = []
        pose: list[list[list[float]]] = []
        seconds: list[float] = []
        for q in range(len(queries)):
            closures, secs = self._ask(pipe, first + q, queries[q])
            kept = [c for c in closures if c.number_of_inliers > self.inliers_threshold
                    and 0 <= c.source_id < ndb]
            index.append([int(c.source_id) for c in kept])
            confidence.append([float(c.number_of_inliers) for c in kept])
            pose.append([relative_pose(c.pose) for c in kept])
            seconds.append(secs)
        return Retrieval.from_lists(index, confidence, pose=pose, seconds=seconds)
