"""The views of any data source: what the map cache, the exporters and the benchmarks call.

A source says what its views are made from (`DataSource.renders`), and this stage makes them:

* "scans" (KITTI and the synthetic default): one pass of sliding local maps over the scans
  (`mapbuild.build_views`), every requested kind from the same maps;
* "images" (top-view image folders, `sources.bev`): the decoded images of the frames, as
  float32 = value / 255, each noisy condition resampled to its moved viewpoint
  (`resample.move_viewpoint`: viewpoint noise cannot re-render an image). `config` is not read:
  the images are what they are.

The rendering lives here, not in the sources, so that the sources need nothing of this later
stage (`docs/architecture.md`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from safl_bench.errors import ConfigError
from safl_bench.sources import DataSource
from safl_bench.views import mapbuild
from safl_bench.views.resample import move_viewpoint

Views = dict[tuple[str, str], np.ndarray | list[np.ndarray]]


def build_views(
    source: DataSource, name: str, config: Any, frames: np.ndarray,
    offsets: Mapping[str, np.ndarray | None], kinds: Sequence[str] = ("topview",),
    progress: bool = True,
) -> Views:
    """Views of `frames` of `source`'s sequence `name` for each named set of viewpoint offsets:
    ``{(label, kind): views}`` (shapes as `mapbuild.build_views`)."""
    if source.renders == "images":
        return _image_views(source, name, frames, offsets, kinds, progress)
    if source.renders != "scans":
        raise ConfigError(f"{source.label}: views made from {source.renders!r}; "
                          "a source renders 'scans' or 'images'")
    # through the module, so that a test that replaces `mapbuild.build_views` sees every call
    return mapbuild.build_views(source.sequence(name), config, frames, offsets, kinds,
                                progress=progress)


def _image_views(source: Any, name: str, frames: np.ndarray,
                 offsets: Mapping[str, np.ndarray | None], kinds: Sequence[str],
                 progress: bool) -> Views:
    for kind in kinds:
        source.check_kind(kind)
    frames = mapbuild.check_frames(frames, len(source.sequence(name)), name)
    steps = np.diff(frames)
    if len(frames) > 1 and steps[0] > 0 and (steps == steps[0]).all():  # a view: no copy
        images = source.images(name, progress=progress)[frames[0]:frames[-1] + 1:steps[0]]
    else:
        images = source.images(name, progress=progress)[frames]
    out: Views = {}
    for label, offset in offsets.items():
        moved = images if offset is None else move_viewpoint(images, offset, source.resolution_m)
        out[label, "topview"] = moved.astype(np.float32) / np.float32(255.0)
    return out
