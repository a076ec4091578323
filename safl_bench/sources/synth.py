"""The embedded synthetic default as a data source: `KittiSource` on the generated root.

The generator (`safl_bench.synth`) writes the KITTI odometry layout, so scans, poses and views
come through the KITTI reader; only the fingerprint differs: it covers the world seed and the
generator's manifest of the sequence (hashed; it records the generator version, seed, settings,
scan sizes and text-file digests, so it changes whenever the generated data does), or the same
file statistics as for KITTI when there is no manifest.

A sequence whose scans are cast on demand (`synth.STREAMED_SEQUENCES`, the long drive) opens as a
`StreamedSequence`: poses, times and calibration from its KITTI text files, each scan cast by the
generator when the map builder reads it (`synth.Scanner`), so the same views come out as from
written scans without 32 GB of them on disk.
"""

from __future__ import annotations

import functools
import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from safl_bench.common.fingerprint import fingerprint
from safl_bench.errors import DataError
from safl_bench.sources.kitti import (
    KittiSequence,
    KittiSource,
    camera_to_lidar_poses,
    read_camera_poses,
    read_times,
    read_tr,
)


@dataclass(frozen=True)
class SynthSource(KittiSource):
    """The synthetic default generated for world seed `seed` (KITTI layout)."""

    seed: int = 0
    #: the synthetic data version (`synth.GENERATOR_VERSIONS`; None: the newest)
    version: str | None = None
    kind: ClassVar[str] = "synth"

    def _open_sequence(self, name: str) -> KittiSequence:
        from safl_bench import synth  # lazy: the generator is heavy

        if synth.is_streamed(self.root, name):
            return open_streamed(self.root, name, self.seed, self.version or synth.GENERATOR_VERSION)
        return super()._open_sequence(name)

    def manifest_digest(self, name: str) -> str | None:
        """SHA-256 of the generator's manifest of sequence `name`, if there is one."""
        from safl_bench.synth.writer import manifest_path  # lazy: the generator is heavy

        path = manifest_path(self.root, name)
        return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None

    def fingerprint(self, name: str) -> str:
        name = str(name)
        manifest = self.manifest_digest(name)
        stats = None if manifest else self.file_stats(name)
        return fingerprint("synth", self.seed, name, manifest, stats)


def synth_source(
    seed: int = 0,
    sequences: Sequence[str] | None = None,
    *,
    progress: bool = True,
    root: Path | None = None,
    version: str | None = None,
) -> SynthSource:
    """The embedded synthetic default for `seed` in data `version` (None: the newest),
    generated first where missing or stale.

    `sequences` defaults to the synthetic test sequences (`safl_bench.synth.TEST_SEQUENCES`).
    """
    from safl_bench import synth  # lazy: the generator is heavy and optional for KITTI users

    version = synth.check_version(version if version is not None else synth.GENERATOR_VERSION)
    names = list(sequences) if sequences is not None else list(synth.TEST_SEQUENCES)
    base = Path(root) if root is not None else synth.default_root(seed, version)
    synth.ensure(base, names, seed=seed, progress=progress, version=version)
    label = f"synthetic default (seed {seed})"
    if version != synth.GENERATOR_VERSION:
        label = f"synthetic default (seed {seed}, data version {version})"
    return SynthSource(root=base, label=label, seed=seed, version=version)


@dataclass
class StreamedSequence(KittiSequence):
    """A synthetic sequence whose scans are cast when read (module doc); `velo_files` is empty."""

    seed: int = 0
    version: str = ""
    #: the generator settings its manifest records (`synth.SynthConfig`), as JSON
    config_json: str = "{}"

    def __len__(self) -> int:
        return len(self.times)

    def scan(self, i: int) -> np.ndarray:
        if not 0 <= i < len(self):
            raise DataError(f"sequence {self.name}: scan index {i} out of range 0..{len(self) - 1}")
        scanner = _scanner(self.name, self.seed, self.version, self.config_json)
        if len(scanner) != len(self):
            raise DataError(f"sequence {self.name} under {self.root}: {len(self)} frames on disk, "
                            f"but its generator settings make {len(scanner)}; regenerate it "
                            f"(safl-bench data synth {self.name})")
        return scanner.scan(int(i))


@functools.lru_cache(maxsize=1)
def _scanner(name: str, seed: int, version: str, config_json: str) -> Any:
    """One `synth.Scanner` per process (its town is drawn once, on the first scan)."""
    import json

    from safl_bench import synth

    return synth.Scanner(name, seed, synth.SynthConfig(**json.loads(config_json)), version=version)


def open_streamed(root: Path, name: str, seed: int, version: str) -> StreamedSequence:
    """Sequence `name` under `root` with its scans cast on demand: its text files read and
    checked as KITTI's are (`sources.kitti`)."""
    import json

    from safl_bench.synth.writer import manifest_path, read_manifest

    seq_dir = root / "sequences" / name
    manifest = read_manifest(root, name)
    if manifest is None or not isinstance(manifest.get("frames"), int):
        raise DataError(f"{manifest_path(root, name)}: missing or unreadable; regenerate the "
                        f"sequence (safl-bench data synth {name})")
    frames = manifest["frames"]
    tr = read_tr(seq_dir / "calib.txt")
    times = read_times(seq_dir / "times.txt", frames)
    camera = read_camera_poses(root / "poses" / f"{name}.txt", frames)
    return StreamedSequence(root=root, name=name, velo_files=[], times=times, tr=tr,
                            _poses=camera_to_lidar_poses(camera, tr), seed=seed, version=version,
                            config_json=json.dumps(manifest["config"], sort_keys=True))
