"""`safl-bench bench images`: reading a top-view image folder, cold and cached.

Cold: a fresh map cache, so every PNG of the sequence is decoded and the uint8 image cache is
written (the PNGs themselves may already be in the OS page cache after the first repeat: the
first repeat is reported apart). Cached: a new source object opening the sequence and reading
the cache file. Views: the float32 views of every frame built from it (value / 255, 4 bytes a
pixel), what a task on all frames does next.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from typing import Any

import numpy as np


def run(root: str, sequence: str, *, repeats: int = 3, resolution_m: float = 0.4) -> dict[str, Any]:
    """Seconds to open and decode (cold) and to read back (cached) every image of `sequence`."""
    from safl_bench.paths import HOME_ENV
    from safl_bench.sources import bev_source
    from safl_bench.views.render import build_views as render_views

    before = os.environ.get(HOME_ENV)
    cold: list[float] = []
    cached: list[float] = []
    views: list[float] = []
    try:
        with tempfile.TemporaryDirectory(prefix="safl-bench-images-") as scratch:
            for i in range(repeats):
                os.environ[HOME_ENV] = os.path.join(scratch, str(i))
                t0 = time.perf_counter()
                n = len(bev_source(root, resolution_m).images(sequence, progress=False))
                cold.append(time.perf_counter() - t0)
            for _ in range(repeats):
                t0 = time.perf_counter()
                source = bev_source(root, resolution_m)
                source.images(sequence, progress=False)
                cached.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                render_views(source, sequence, None, np.arange(n), {"clean": None}, progress=False)
                views.append(time.perf_counter() - t0)
    finally:
        if before is None:
            os.environ.pop(HOME_ENV, None)
        else:
            os.environ[HOME_ENV] = before
    return {"root": str(root), "sequence": sequence, "images": n, "repeats": repeats,
            "cold_first_s": cold[0], "cold_median_s": statistics.median(cold),
            "cached_median_s": statistics.median(cached), "views_median_s": statistics.median(views),
            "cold_s": cold, "cached_s": cached, "views_s": views}


def format_results(r: dict[str, Any]) -> str:
    """The figures as a few lines of text."""
    return "\n".join([
        f"top-view images {r['root']} sequence {r['sequence']}: {r['images']} images, {r['repeats']} repeats",
        f"  cold (decode every PNG, write the cache): first {r['cold_first_s']:.2f} s, "
        f"median {r['cold_median_s']:.2f} s",
        f"  cached (open the sequence, read the cache): median {r['cached_median_s']:.2f} s",
        f"  float32 views of every frame from the cache: median {r['views_median_s']:.2f} s",
    ])
