"""Data sources, one file each: where the frames of a sequence and their views come from.

* `kitti`: a KITTI odometry root (scans, poses, calibration, times), read with pykitti;
* `synth`: the embedded synthetic default, generated on first use in the same layout;
* `bev`: folders of per-frame top-view images with poses (BEVPlace's published KITTI layout).

All three implement `DataSource` (`base`); a new dataset or layout is one new file here and one
entry in `open_source`. Task specs name a source by its `kind`: "kitti", "synth" or "bev".
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

from safl_bench.errors import ConfigError, DataError
from safl_bench.sources.base import DataSource
from safl_bench.sources.bev import (
    BEV_ROOT_ENV,
    BEV_ROT_ROOT_ENV,
    DEFAULT_RESOLUTION_M,
    ROTATED_LABELS,
    BevSource,
    bev_source,
    check_same_frames,
)
from safl_bench.sources.kitti import KittiSource, kitti_source
from safl_bench.sources.synth import SynthSource, synth_source

KINDS = ("synth", "kitti", "bev")


class SourceSpec(Protocol):
    """What `open_source` reads of a task's spec (`safl_bench.tasks.spec.TaskSpec` has it; the
    tasks come after the sources, so this stage names only the fields)."""

    @property
    def id(self) -> str: ...
    @property
    def source(self) -> str: ...
    @property
    def data_seed(self) -> int: ...
    @property
    def sequence(self) -> str: ...
    @property
    def rotated(self) -> str | None: ...
    @property
    def data_version(self) -> str | None: ...

#: The option that points each real source at its data (for error messages).
ROOT_OPTION = {"kitti": "--kitti-root DIR", "bev": "--bev-root DIR"}
#: The option that points the rotated top-view tasks at their second image folder.
ROT_ROOT_OPTION = "--bev-rot-root DIR"

__all__ = [
    "BEV_ROOT_ENV", "BEV_ROT_ROOT_ENV", "DEFAULT_RESOLUTION_M", "KINDS", "ROT_ROOT_OPTION",
    "BevSource", "DataSource", "KittiSource", "SynthSource", "bev_source", "kitti_source",
    "missing_data", "open_query_source", "open_source", "real_roots", "resolve_source", "root_options",
    "synth_source",
]


def root_options(kind: str, rotated: str | None = None) -> str:
    """The data options a task on `kind` data needs, its image folders by `TaskSpec.rotated`
    (e.g. '--bev-root DIR --bev-rot-root DIR'); '' for the synthetic default."""
    if rotated == "both":
        return ROT_ROOT_OPTION
    plain = ROOT_OPTION.get(kind, "")
    return f"{plain} {ROT_ROOT_OPTION}" if rotated == "queries" else plain


def real_roots(kitti_root: str | os.PathLike[str] | None,
               bev_root: str | os.PathLike[str] | None) -> tuple[str | None, str | None]:
    """The KITTI and top-view roots a command was given (options first, then $SAFL_KITTI_ROOT and
    $SAFL_BEV_ROOT); both at once is an error: a run reads one real source."""
    if kitti_root is not None and bev_root is not None:
        raise ConfigError("--kitti-root and --bev-root name two data sources; give one of them")
    return (None if kitti_root is None else str(kitti_root), None if bev_root is None else str(bev_root))


def resolve_source(
    kitti_root: str | Path | None,
    *,
    bev_root: str | Path | None = None,
    bev_resolution_m: float = DEFAULT_RESOLUTION_M,
    sequences: Sequence[str] | None = None,
    seed: int = 0,
    progress: bool = True,
) -> DataSource:
    """KITTI at `kitti_root`, the top-view images at `bev_root`, else the synthetic default
    (generated if missing)."""
    real_roots(kitti_root, bev_root)
    if kitti_root is not None:
        return kitti_source(kitti_root)
    if bev_root is not None:
        return bev_source(bev_root, bev_resolution_m)
    return synth_source(seed, sequences, progress=progress)


def open_source(spec: SourceSpec, *, kitti_root: str | None = None, bev_root: str | None = None,
                bev_resolution_m: float = DEFAULT_RESOLUTION_M, progress: bool = True,
                bev_rot_root: str | None = None) -> DataSource:
    """The data source of a task's database: the embedded default (generated on first use), the
    KITTI root (`kitti_root`, else $SAFL_KITTI_ROOT) or the top-view images (`bev_root`, else
    $SAFL_BEV_ROOT; a task whose database is rotated: `bev_rot_root`, else $SAFL_BEV_ROT_ROOT).
    A rotated task's source carries its label (`ROTATED_LABELS`)."""
    from safl_bench import paths

    if spec.source == "synth":
        return synth_source(seed=spec.data_seed, sequences=(spec.sequence,), progress=progress,
                            version=spec.data_version)
    rotated = getattr(spec, "rotated", None)
    if spec.source == "bev" and rotated == "both":
        return bev_source(_rot_root(spec, bev_rot_root), bev_resolution_m, ROTATED_LABELS[rotated])
    explicit = kitti_root if spec.source == "kitti" else bev_root
    env = paths.KITTI_ROOT_ENV if spec.source == "kitti" else BEV_ROOT_ENV
    value = explicit if explicit is not None else os.environ.get(env)
    if not value:
        raise DataError(f"task {spec.id} needs its data: pass {ROOT_OPTION[spec.source]} or set {env}")
    if spec.source == "kitti":
        return kitti_source(paths.kitti_root(value))
    if rotated is not None:
        return bev_source(value, bev_resolution_m, ROTATED_LABELS[rotated])
    return bev_source(value, bev_resolution_m)


def missing_data(spec: SourceSpec, *, kitti_root: str | None = None, bev_root: str | None = None,
                 bev_rot_root: str | None = None) -> str | None:
    """What `open_source` and `open_query_source` would refuse for want of a data folder (the
    option or environment variable that names it), without opening anything; None when every
    folder the task reads is named. Commands call it before any work."""
    from safl_bench import paths

    if spec.source == "synth":
        return None
    rotated = getattr(spec, "rotated", None)
    if spec.source == "bev" and rotated in ("both", "queries") and not (
            bev_rot_root or os.environ.get(BEV_ROT_ROOT_ENV)):
        return (f"task {spec.id} needs the rotated top-view images (BEVPlace's KITTIRot): pass "
                f"{ROT_ROOT_OPTION} or set {BEV_ROT_ROOT_ENV}")
    if rotated == "both":
        return None
    explicit = kitti_root if spec.source == "kitti" else bev_root
    env = paths.KITTI_ROOT_ENV if spec.source == "kitti" else BEV_ROOT_ENV
    if not (explicit or os.environ.get(env)):
        return f"task {spec.id} needs its data: pass {ROOT_OPTION[spec.source]} or set {env}"
    return None


def _rot_root(spec: SourceSpec, bev_rot_root: str | None) -> str:
    value = bev_rot_root if bev_rot_root is not None else os.environ.get(BEV_ROT_ROOT_ENV)
    if not value:
        raise DataError(f"task {spec.id} needs the rotated top-view images (BEVPlace's KITTIRot): "
                        f"pass {ROT_ROOT_OPTION} or set {BEV_ROT_ROOT_ENV}")
    return value


def open_query_source(spec: SourceSpec, database: DataSource, *, bev_rot_root: str | None = None,
                      bev_resolution_m: float = DEFAULT_RESOLUTION_M) -> DataSource | None:
    """The source of a task's queries where it is not its database's: the second image folder
    (`bev_rot_root`, else $SAFL_BEV_ROT_ROOT) of a task whose queries are rotated, checked to
    hold the database folder's frames and poses (`check_same_frames`); None for any other task."""
    if getattr(spec, "rotated", None) != "queries":
        return None
    queries = bev_source(_rot_root(spec, bev_rot_root), bev_resolution_m, database.label)
    if Path(queries.root).resolve() == Path(database.root).resolve():
        raise DataError(f"task {spec.id}: the rotated images ({ROT_ROOT_OPTION}) and the plain ones "
                        f"(--bev-root) are the same folder {queries.root}")
    check_same_frames(database.sequence(spec.sequence), queries.sequence(spec.sequence))
    return queries
