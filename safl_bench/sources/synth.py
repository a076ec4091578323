"""The embedded synthetic default as a data source: `KittiSource` on the generated root.

The generator (`safl_bench.synth`) writes the KITTI odometry layout, so scans, poses and views
come through the KITTI reader; only the fingerprint differs: it covers the world seed and the
generator's manifest of the sequence (hashed; it records the generator version, seed, settings,
scan sizes and text-file digests, so it changes whenever the generated data does), or the same
file statistics as for KITTI when there is no manifest.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from safl_bench.common.fingerprint import fingerprint
from safl_bench.sources.kitti import KittiSource


@dataclass(frozen=True)
class SynthSource(KittiSource):
    """The synthetic default generated for world seed `seed` (KITTI layout)."""

    seed: int = 0
    #: the synthetic data version (`synth.GENERATOR_VERSIONS`; None: the newest)
    version: str | None = None
    kind: ClassVar[str] = "synth"

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
