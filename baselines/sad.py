"""SAD: SeqSLAM's hand-crafted descriptor (Milford & Wyeth 2012), the paper's first baseline.

describe: each top-view map is downsampled by block averaging to `size` x `size` pixels
(64x64 -> 32x32 by default; SeqSLAM shrinks camera images to 64x32, a square top view keeps its
aspect), then patch-normalised: every non-overlapping `patch` x `patch` block (8 by default, as
in SeqSLAM) is shifted to zero mean and divided by its range (max - min), as OpenSeqSLAM's
`patchNormalize` does (mode "range"; a constant patch becomes 0). Mode "zscore" divides by the
standard deviation instead (OpenSeqSLAM's other mode). The descriptor is the flattened image,
`size*size` float32 values.

distance: the sum of absolute differences divided by the number of pixels (SeqSLAM's
difference matrix), computed with torch.cdist(p=1) in query chunks: no Python loop over pairs.
"""

from __future__ import annotations

import numpy as np
import torch

from safl_bench.errors import ConfigError, DataError
from safl_bench.method import Method, Views, as_topview
from safl_bench.method_registry import register_method

NORMALISATIONS = ("range", "zscore")


def block_mean(maps: np.ndarray, size: int) -> np.ndarray:
    """Downsample (N, H, W) to (N, size, size) by averaging blocks (area interpolation)."""
    n, h, w = maps.shape
    if h % size == 0 and w % size == 0:
        return maps.reshape(n, size, h // size, size, w // size).mean(axis=(2, 4), dtype=np.float32)
    t = torch.from_numpy(np.ascontiguousarray(maps))[:, None]
    return torch.nn.functional.adaptive_avg_pool2d(t, size)[:, 0].numpy()


def patch_normalise(images: np.ndarray, patch: int, mode: str = "range") -> np.ndarray:
    """Normalise every non-overlapping patch x patch block of (N, S, S) images (vectorised)."""
    n, s, _ = images.shape
    k = s // patch
    blocks = images.reshape(n, k, patch, k, patch).astype(np.float32, copy=False)
    mean = blocks.mean(axis=(2, 4), keepdims=True)
    if mode == "range":
        scale = blocks.max(axis=(2, 4), keepdims=True) - blocks.min(axis=(2, 4), keepdims=True)
    else:
        scale = blocks.std(axis=(2, 4), keepdims=True)
    inv = np.zeros_like(scale)
    np.divide(np.float32(1.0), scale, out=inv, where=scale > 1e-6)  # constant patch -> 0
    return ((blocks - mean) * inv).reshape(n, s, s)


@register_method
class SAD(Method):
    """SeqSLAM's downsampled, patch-normalised map with the sum of absolute differences."""

    name = "sad"
    version = "1"

    def __init__(self, size: int = 32, patch: int = 8, normalisation: str = "range", chunk_rows: int = 1024):
        self.size = size
        self.patch = patch
        self.normalisation = normalisation
        self.chunk_rows = chunk_rows

    runtime_params = ("chunk_rows",)

    def _validate(self) -> None:
        if not isinstance(self.size, int) or self.size < 1:
            raise ConfigError(f"sad: size must be a positive integer, got {self.size!r}")
        if not isinstance(self.patch, int) or self.patch < 1 or self.size % self.patch:
            raise ConfigError(f"sad: patch must divide size={self.size}, got {self.patch!r}")
        if self.normalisation not in NORMALISATIONS:
            raise ConfigError(f"sad: normalisation must be one of {NORMALISATIONS}, got {self.normalisation!r}")
        if not isinstance(self.chunk_rows, int) or self.chunk_rows < 1:
            raise ConfigError(f"sad: chunk_rows must be a positive integer, got {self.chunk_rows!r}")

    def describe(self, maps: Views) -> np.ndarray:
        """(N, size*size) float32 patch-normalised thumbnails."""
        self._validate()
        arr = as_topview(maps)
        if arr.shape[1] < self.size or arr.shape[2] < self.size:
            raise DataError(f"sad: maps of {arr.shape[1]}x{arr.shape[2]} are smaller than size={self.size}")
        small = block_mean(arr, self.size)
        return patch_normalise(small, self.patch, self.normalisation).reshape(len(arr), -1)

    def distance(self, queries: np.ndarray, database: np.ndarray) -> np.ndarray:
        """Mean absolute difference per pixel, (Nq, Ndb) float32."""
        self._validate()
        q = torch.from_numpy(np.ascontiguousarray(queries, dtype=np.float32))
        d = torch.from_numpy(np.ascontiguousarray(database, dtype=np.float32))
        if q.ndim != 2 or d.ndim != 2 or q.shape[1] != d.shape[1]:
            raise DataError(f"sad: descriptor shapes do not match: {tuple(q.shape)} vs {tuple(d.shape)}")
        out = np.empty((q.shape[0], d.shape[0]), np.float32)
        for lo in range(0, q.shape[0], self.chunk_rows):
            hi = min(lo + self.chunk_rows, q.shape[0])
            out[lo:hi] = torch.cdist(q[lo:hi], d, p=1).numpy()
        out /= np.float32(max(q.shape[1], 1))
        return out
