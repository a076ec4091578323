"""`DataSource`: the interface every data source implements (KITTI scans, the synthetic default,
top-view image folders; one file each in this package).

A source opens sequences by name and says how its views are made; the views stage renders them
(`safl_bench.views.render.build_views`), so that this stage needs nothing of a later one:

* `sequence(name)` (opened once) has `positions` (n, 2) ground-plane metres, `times` (n,) s and
  `len()`: all that tasks and ground truth need;
* `fingerprint(name)` is a cheap digest of the sequence's files for cache keys (no file is hashed
  in full: KITTI is 80 GB);
* `renders` says what its views are made from: "scans" (sliding local maps of LiDAR scans,
  `sequence(name)` being a `KittiSequence`) or "images" (top-view images, `images(name)`);
* `view_kinds` says which views it can render (an image folder has no points), `cache_views`
  whether rendered views are worth keeping in the map cache (re-rendering from scans is slow;
  resampling an image is not), and `notes(name)` what a record must say about the data (e.g.
  timestamps that were assumed).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Protocol

import numpy as np

from safl_bench.errors import DataError


def file_stat(path: Path) -> list[int] | None:
    """[size, mtime in ns] of a file, None when it does not exist (cheap cache-key material)."""
    try:
        st = path.stat()
    except FileNotFoundError:
        return None
    return [st.st_size, st.st_mtime_ns]


class Frames(Protocol):
    """What a source's opened sequence offers the tasks."""

    name: str
    times: np.ndarray

    def __len__(self) -> int: ...

    @property
    def positions(self) -> np.ndarray: ...


@dataclass(frozen=True)
class DataSource:
    """A dataset root and what it is (for tables and cache keys); subclasses say how to read it."""

    root: Path
    label: str
    _open: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    #: "synth", "kitti" or "bev": what task specs and records name as their source.
    kind: ClassVar[str] = ""
    view_kinds: ClassVar[tuple[str, ...]] = ("topview", "points")
    cache_views: ClassVar[bool] = True
    #: what the views are made from: "scans" (local maps of LiDAR scans) or "images"
    renders: ClassVar[str] = "scans"

    def sequence(self, name: str) -> Any:
        """Open (once) and return sequence `name`."""
        name = str(name)
        if name not in self._open:
            self._open[name] = self._open_sequence(name)
        return self._open[name]

    def _open_sequence(self, name: str) -> Any:
        raise NotImplementedError

    def fingerprint(self, name: str) -> str:
        """Cheap fingerprint of sequence `name` of this source (for cache keys)."""
        raise NotImplementedError

    def notes(self, name: str) -> list[str]:
        """What a result record must say about this sequence's data (none by default)."""
        return []

    def check_kind(self, kind: str, purpose: str = "") -> None:
        """DataError in one line when this source cannot render views of `kind`."""
        if kind not in self.view_kinds:
            why = f" ({purpose})" if purpose else ""
            raise DataError(
                f"{self.label} at {self.root} has no {kind} views{why}: it has only "
                f"{', '.join(self.view_kinds)}; run point-cloud methods on KITTI scans "
                "(--kitti-root) or on the synthetic default"
            )
