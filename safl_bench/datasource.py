"""Where scans come from: the synthetic default or a KITTI odometry root (same layout, same reader).

A `DataSource` opens sequences and gives each a cheap fingerprint for cache keys: no file is
hashed in full (KITTI is 80 GB). For KITTI it covers the root path, the sizes and modification
times of poses/calib/times and the number of scans; for the synthetic default it covers the seed
and the generator's manifest of the sequence (hashed), or the same file statistics as for KITTI
when there is no manifest.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from safl_bench.errors import ConfigError, DataError
from safl_bench.fingerprint import fingerprint
from safl_bench.kitti import KittiSequence, open_sequence

KINDS = ("synth", "kitti")


def _stat(path: Path) -> list[int] | None:
    try:
        st = path.stat()
    except FileNotFoundError:
        return None
    return [st.st_size, st.st_mtime_ns]


@dataclass(frozen=True)
class DataSource:
    """A dataset root in the KITTI odometry layout and what it is (for tables and cache keys)."""

    kind: str
    root: Path
    label: str
    seed: int | None = None
    _open: dict[str, KittiSequence] = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ConfigError(f"data source kind must be one of {', '.join(KINDS)}, got {self.kind!r}")

    def sequence(self, name: str) -> KittiSequence:
        """Open (once) and return sequence `name`."""
        name = str(name)
        if name not in self._open:
            self._open[name] = open_sequence(self.root, name)
        return self._open[name]

    def file_stats(self, name: str) -> dict[str, object]:
        """Sizes and mtimes of the sequence's text files and its scan count (no reading)."""
        seq_dir = self.root / "sequences" / name
        velo = seq_dir / "velodyne"
        return {
            "poses": _stat(self.root / "poses" / f"{name}.txt"),
            "calib": _stat(seq_dir / "calib.txt"),
            "times": _stat(seq_dir / "times.txt"),
            "scans": sum(1 for _ in velo.glob("*.bin")) if velo.is_dir() else 0,
        }

    def manifest_digest(self, name: str) -> str | None:
        """SHA-256 of the synthetic generator's manifest of sequence `name`, if there is one.

        The manifest records the generator version, seed, settings, scan sizes and text-file
        digests, so it changes whenever the generated data does.
        """
        from safl_bench.synth.writer import manifest_path  # lazy: only synthetic sources

        path = manifest_path(self.root, name)
        return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None

    def fingerprint(self, name: str) -> str:
        """Cheap fingerprint of sequence `name` of this source (for map-cache keys)."""
        name = str(name)
        if self.kind == "synth":
            manifest = self.manifest_digest(name)
            stats = None if manifest else self.file_stats(name)
            return fingerprint("synth", self.seed, name, manifest, stats)
        return fingerprint("kitti", str(self.root.resolve()), name, self.file_stats(name))


def kitti_source(root: str | Path) -> DataSource:
    """A KITTI odometry root (or any directory in its layout)."""
    path = Path(root).expanduser()
    if not path.is_dir():
        raise DataError(f"KITTI root {path} does not exist or is not a directory")
    return DataSource(kind="kitti", root=path, label="KITTI")


def synth_source(
    seed: int = 0,
    sequences: Sequence[str] | None = None,
    *,
    progress: bool = True,
    root: Path | None = None,
) -> DataSource:
    """The embedded synthetic default for `seed`, generated first where missing or stale.

    `sequences` defaults to the synthetic test sequences (`safl_bench.synth.TEST_SEQUENCES`).
    """
    from safl_bench import synth  # lazy: the generator is heavy and optional for KITTI users

    names = list(sequences) if sequences is not None else list(synth.TEST_SEQUENCES)
    base = Path(root) if root is not None else synth.default_root(seed)
    synth.ensure(base, names, seed=seed, progress=progress)
    return DataSource(kind="synth", root=base, label=f"synthetic default (seed {seed})", seed=seed)


def resolve_source(
    kitti_root: str | Path | None,
    *,
    sequences: Sequence[str] | None = None,
    seed: int = 0,
    progress: bool = True,
) -> DataSource:
    """KITTI at `kitti_root` when given, else the synthetic default (generated if missing)."""
    if kitti_root is not None:
        return kitti_source(kitti_root)
    return synth_source(seed, sequences, progress=progress)
