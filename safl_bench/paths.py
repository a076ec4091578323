"""Where safl-bench keeps its data, caches and results, and where KITTI is.

Everything lives under one home directory, `$SAFL_HOME` or `~/.cache/safl-bench`:

    <home>/synth/        the embedded default dataset, in the KITTI odometry layout
    <home>/maps/         cached top-view maps, keyed by every setting that changes them
    <home>/weights/      trained weights written by `safl-bench train`
"""

from __future__ import annotations

import os
from pathlib import Path

from safl_bench.errors import DataError

KITTI_ROOT_ENV = "SAFL_KITTI_ROOT"
HOME_ENV = "SAFL_HOME"


def home() -> Path:
    """The directory under which safl-bench caches data (created on demand)."""
    env = os.environ.get(HOME_ENV)
    return Path(env).expanduser() if env else Path.home() / ".cache" / "safl-bench"


def synth_root() -> Path:
    """Root of the embedded default dataset (KITTI odometry layout)."""
    return home() / "synth"


def map_cache_dir() -> Path:
    """Directory of the cached top-view maps."""
    return home() / "maps"


def kitti_root(explicit: str | os.PathLike[str] | None = None) -> Path:
    """The KITTI odometry root from `--kitti-root` or `$SAFL_KITTI_ROOT`.

    Raises DataError naming both ways to set it when neither is given or the directory is missing.
    """
    value = explicit if explicit is not None else os.environ.get(KITTI_ROOT_ENV)
    if not value:
        raise DataError(
            f"KITTI tasks need the KITTI odometry root: pass --kitti-root DIR or set {KITTI_ROOT_ENV}"
        )
    root = Path(value).expanduser()
    if not root.is_dir():
        raise DataError(f"KITTI root {root} does not exist or is not a directory")
    return root
