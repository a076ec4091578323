"""Resampling finished top-view images: to another viewpoint, and to a method's input size.

Sources with points re-render a view from the local map (`safl_bench.views.topview`); an image source
has nothing to re-render from, so its noisy queries are the image resampled to the moved
viewpoint. Choices, and why:
- `move_viewpoint` uses the viewpoint offsets of `safl_bench.views.noise` exactly as the renderer does
  ([dx, dy] metres in the robot frame, x forward, y left, and dtheta rad): the output shows what
  lies around the moved viewpoint. Nearest-neighbour sampling keeps the image's value levels
  (a count image stays a count image; interpolation would blur every query but no database
  image). What the moved view sees beyond the original image is empty (0): a 20 m shift of a
  60.4 m wide view leaves up to a third of it empty along an axis, and rotations empty the
  corners (`coverage` measures it, `coverage_masks` shows where).
- The sampling is scipy's `affine_transform(order=0, mode="constant", cval=0)` on each image, done
  for the whole stack in one numba kernel (parallel over images): the same double-precision
  coordinate, summed in scipy's order (shift, then row, then column term), inside when it lies in
  [0, S - 1], the nearest index `floor(x + 0.5)`. The output is bit-identical to scipy's (the tests
  compare both), so records made before are reproduced, at about a tenth of the per-image loop's
  time: the viewpoint move was the largest per-seed cost of a noisy image cell.
- `fit_input` gives a method its declared input size (`Method.input_size`) by bilinear
  interpolation with antialiasing (area-like when shrinking, smooth when enlarging), so a
  64 x 64 network runs on 151 x 151 images; the runner records the sizes.
"""

from __future__ import annotations

import numba
import numpy as np

from safl_bench.errors import ConfigError


def _affine(size: int, offset: np.ndarray, resolution_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(matrix, offset) of scipy's affine_transform: output index (r, c) -> input index."""
    dx, dy, dtheta = (float(v) for v in offset)
    c, s = np.cos(dtheta), np.sin(dtheta)
    rot = np.array([[c, -s], [s, c]])  # acts on (forward, left); (r, c) indices flip both signs
    centre = np.full(2, (size - 1) / 2.0)
    shift = np.array([dx, dy]) / resolution_m
    return rot, centre - rot @ centre - shift


def move_viewpoint(images: np.ndarray, offsets: np.ndarray, resolution_m: float) -> np.ndarray:
    """Each (S, S) image of `images` (N, S, S) seen from its viewpoint moved by `offsets[i]`
    ([dx, dy] m in the robot frame, dtheta rad); same dtype, nearest neighbour, 0 outside."""
    images = np.asarray(images)
    offsets = np.asarray(offsets, dtype=np.float64)
    if images.ndim != 3 or images.shape[1] != images.shape[2]:
        raise ConfigError(f"need (N, S, S) images, got {images.shape}")
    if offsets.shape != (len(images), 3):
        raise ConfigError(f"need ({len(images)}, 3) viewpoint offsets, got {offsets.shape}")
    matrices = np.empty((len(images), 2, 2))
    shifts = np.empty((len(images), 2))
    for i in range(len(images)):
        matrices[i], shifts[i] = _affine(images.shape[1], offsets[i], resolution_m)
    out = np.empty_like(images)
    if len(images):
        _nearest_kernel(np.ascontiguousarray(images), matrices, shifts, out)
    return out


@numba.njit(parallel=True, cache=True)
def _nearest_kernel(images, matrices, shifts, out):
    """out[i] = images[i] sampled at shifts[i] + matrices[i] @ (r, c), nearest, 0 outside."""
    n, size = images.shape[0], images.shape[1]
    last = size - 1.0
    for i in numba.prange(n):
        m00, m01 = matrices[i, 0, 0], matrices[i, 0, 1]
        m10, m11 = matrices[i, 1, 0], matrices[i, 1, 1]
        for r in range(size):
            fr = float(r)
            for c in range(size):
                fc = float(c)
                a = shifts[i, 0]
                a += fr * m00
                a += fc * m01
                b = shifts[i, 1]
                b += fr * m10
                b += fc * m11
                if a >= 0.0 and a <= last and b >= 0.0 and b <= last:
                    out[i, r, c] = images[i, int(np.floor(a + 0.5)), int(np.floor(b + 0.5))]
                else:
                    out[i, r, c] = 0


def coverage_masks(size: int, offsets: np.ndarray, resolution_m: float) -> np.ndarray:
    """(N, size, size) uint8: 1 where each moved view still sees the original image, 0 where
    `move_viewpoint` leaves it empty."""
    ones = np.ones((len(offsets), size, size), dtype=np.uint8)
    return move_viewpoint(ones, offsets, resolution_m)


def coverage(size: int, offsets: np.ndarray, resolution_m: float) -> np.ndarray:
    """(N,) fraction of each moved view that still lies inside the original image."""
    return coverage_masks(size, offsets, resolution_m).mean(axis=(1, 2))


def fit_input(maps: np.ndarray, size: int | None) -> np.ndarray:
    """(N, H, W) maps resampled to (N, size, size) (bilinear, antialiased); unchanged when
    `size` is None or already the maps' size."""
    import torch

    arr = np.asarray(maps)
    if size is None or arr.shape[1:] == (size, size) or arr.ndim != 3:
        return arr
    t = torch.from_numpy(np.ascontiguousarray(arr, dtype=np.float32))[:, None]
    out = torch.nn.functional.interpolate(t, size=(size, size), mode="bilinear",
                                          align_corners=False, antialias=True)[:, 0]
    return out.clamp_(0.0, 1.0).numpy()
