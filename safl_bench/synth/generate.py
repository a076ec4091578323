"""Generate synthetic sequences on disk, and only those that are missing or stale.

A sequence is current when its manifest (written last, atomically) matches the generator
version, the seed and the config, and every file it lists exists with the recorded size (scans)
or checksum (text files). Anything else, such as a run interrupted half-way, is regenerated.
Sequences are independent (each seeded from the seed and its own name), so generating two at
once in threads (the ray caster releases the GIL) gives the same bytes as one after another.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench import paths
from safl_bench.common.atomic import atomic_write_json
from safl_bench.common.fingerprint import to_jsonable
from safl_bench.errors import DataError
from safl_bench.synth import writer
from safl_bench.synth.config import (
    ALL_SEQUENCES,
    GENERATOR_VERSION,
    GENERATOR_VERSIONS,
    STREAMED_SEQUENCES,
    SynthConfig,
    sequence_seed,
)
from safl_bench.synth.lidar import Lidar
from safl_bench.synth.routes import ROUTE_RULES, Trajectory, plan_trajectory, sensor_poses
from safl_bench.synth.streets import StreetGrid, make_street_grid
from safl_bench.synth.world import World, make_world

#: threads used to generate several sequences at once (the machine this targets has 2 cores)
WORKERS = 2


def check_version(version: str) -> str:
    """`version` as a data version this generator makes; DataError naming the ones it does."""
    version = str(version)
    if version not in GENERATOR_VERSIONS:
        raise DataError(f"this safl-bench generates synthetic data versions {', '.join(GENERATOR_VERSIONS)}, "
                        f"not {version!r}")
    return version


def default_root(seed: int = 0, version: str = GENERATOR_VERSION) -> Path:
    """Where the default synthetic dataset for `seed` lives: `seed-<seed>` for data version 5
    (where it always lived, so its caches stay valid), `v<version>/seed-<seed>` for the others."""
    version = check_version(version)
    if version == "5":
        return paths.synth_root() / f"seed-{seed}"
    return paths.synth_root() / f"v{version}" / f"seed-{seed}"


@dataclass
class Scene:
    """Everything needed to render one sequence: its streets, route, world and sensor."""

    name: str
    seed: int
    config: SynthConfig
    version: str
    grid: StreetGrid
    trajectory: Trajectory
    poses: np.ndarray  # (n,4,4) world poses of the LiDAR
    rngs: list[np.random.Generator]

    def lidar_poses(self) -> np.ndarray:
        """Poses relative to the first scan (the first one is the identity), as KITTI's."""
        rel = np.linalg.inv(self.poses[0]) @ self.poses
        rel[0] = np.eye(4)
        return rel


def make_route(name: str, seed: int = 0, config: SynthConfig | None = None,
               version: str = GENERATOR_VERSION) -> Scene:
    """The streets and route of a sequence of data `version`, without drawing the town (cheap)."""
    config = config or SynthConfig()
    version = check_version(version)
    spec = config.spec(name, version)
    # streets, town, route, sensor, lateral wander (the fifth, added in data version 3, leaves
    # the first four as they were)
    rngs = [np.random.default_rng(s) for s in sequence_seed(seed, name).spawn(5)]
    grid = make_street_grid(spec.grid_lines, rngs[0])
    traj = plan_trajectory(grid, spec.frames, rngs[2], wander_rng=rngs[4], revisits=spec.revisits,
                           rate_hz=config.rate_hz, rule=ROUTE_RULES[version])
    return Scene(name, seed, config, version, grid, traj, sensor_poses(traj, config.sensor_height_m), rngs)


def make_scene_world(scene: Scene) -> tuple[World, Lidar]:
    """Draw the town and build the sensor of a scene."""
    world = make_world(scene.grid, scene.rngs[1], scene.config.cell_m)
    return world, Lidar(scene.config, scene.rngs[3])


class Scanner:
    """The scans of one sequence, each cast when asked for: scan `i` is the same array whether
    it is written to disk (`generate_sequence`) or cast on demand (`STREAMED_SEQUENCES`), since
    every scan draws only from its own key and azimuth offset. The town is drawn on the first
    scan (seconds to a minute, and about 1.5 GB for the long drive's town)."""

    def __init__(self, name: str, seed: int = 0, config: SynthConfig | None = None,
                 version: str = GENERATOR_VERSION) -> None:
        self.scene = make_route(name, seed, config, version)
        self.lidar = Lidar(self.scene.config, self.scene.rngs[3])
        n = len(self.scene.trajectory)
        sensor_rng = self.scene.rngs[3]
        self.keys = sensor_rng.integers(0, 2**63 - 1, size=n, dtype=np.int64)
        self.offsets = sensor_rng.uniform(0.0, np.radians(self.scene.config.azimuth_res_deg), size=n)
        self._world: World | None = None
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self.keys)

    def world(self) -> World:
        with self._lock:
            if self._world is None:
                self._world = make_world(self.scene.grid, self.scene.rngs[1], self.scene.config.cell_m)
            return self._world

    def scan(self, i: int) -> np.ndarray:
        """Scan `i` as float32 (N, 4) in the sensor frame."""
        return self.lidar.scan(self.world(), self.scene.poses[i], int(self.keys[i]),
                               float(self.offsets[i]))


def _expected_manifest(name: str, seed: int, config: SynthConfig, version: str) -> dict[str, Any]:
    out: dict[str, Any] = {
        "generator_version": version,
        "sequence": name,
        "seed": int(seed),
        "config": to_jsonable(config),
    }
    if name in STREAMED_SEQUENCES:  # only there, so that the written sequences' manifests stay valid
        out["scans"] = CAST_ON_DEMAND
    return out


#: What the manifest of a sequence of `STREAMED_SEQUENCES` says of its scans.
CAST_ON_DEMAND = "cast on demand"


def is_streamed(root: Path, name: str) -> bool:
    """Whether sequence `name` under `root` has its scans cast on demand (its manifest says so)."""
    manifest = writer.read_manifest(root, name)
    return manifest is not None and manifest.get("scans") == CAST_ON_DEMAND


def is_current(root: Path, name: str, seed: int = 0, config: SynthConfig | None = None,
               version: str = GENERATOR_VERSION) -> bool:
    """Whether sequence `name` under `root` is complete and made with these settings."""
    config = config or SynthConfig()
    manifest = writer.read_manifest(root, name)
    if manifest is None:
        return False
    expected = _expected_manifest(name, seed, config, version)
    if any(manifest.get(k) != v for k, v in expected.items()):
        return False
    if name not in STREAMED_SEQUENCES:
        sizes = manifest.get("scan_bytes", [])
        if len(sizes) != manifest.get("frames"):
            return False
        velodyne = writer.sequence_dir(root, name) / "velodyne"
        try:
            on_disk = {p.name: p.stat().st_size for p in velodyne.glob("*.bin")}
        except OSError:
            return False
        if on_disk != {f"{i:06d}.bin": size for i, size in enumerate(sizes)}:
            return False
    for rel, digest in manifest.get("text_sha256", {}).items():
        file = root / rel
        if not file.is_file() or writer.file_sha256(file) != digest:
            return False
    return True


def generate_sequence(root: Path, name: str, seed: int = 0, config: SynthConfig | None = None,
                      on_frame: Callable[[], None] | None = None,
                      version: str = GENERATOR_VERSION) -> None:
    """Generate sequence `name` of data `version` under `root` (overwriting whatever is there):
    its scans, text files and manifest; for a sequence of `STREAMED_SEQUENCES` the text files and
    manifest only (its scans are cast on demand, `Scanner`)."""
    config = config or SynthConfig()
    scanner = Scanner(name, seed, config, version)
    scene = scanner.scene
    manifest = writer.manifest_path(root, name)
    manifest.unlink(missing_ok=True)  # from here on the sequence reads as incomplete
    velodyne = writer.sequence_dir(root, name) / "velodyne"
    velodyne.mkdir(parents=True, exist_ok=True)
    n = len(scene.trajectory)
    streamed = name in STREAMED_SEQUENCES
    for stale in velodyne.glob("*.bin"):
        if streamed or not stale.stem.isdigit() or int(stale.stem) >= n:
            stale.unlink()
    sizes = []
    for i in range(0 if streamed else n):
        sizes.append(writer.write_scan(root, name, i, scanner.scan(i)))
        if on_frame is not None:
            on_frame()
    digests = writer.write_text_files(root, name, scene.lidar_poses(), scene.trajectory.times)
    atomic_write_json(manifest, {
        **_expected_manifest(name, seed, config, scene.version),
        "frames": n,
        "scan_bytes": sizes,
        "text_sha256": digests,
    })


def ensure(root: Path, sequences: Sequence[str], seed: int = 0, progress: bool = True,
           config: SynthConfig | None = None, version: str = GENERATOR_VERSION) -> None:
    """Generate the sequences of data `version` under `root` that are missing or stale; keep
    the others."""
    config = config or SynthConfig()
    version = check_version(version)
    root = Path(root)
    if root.exists() and not root.is_dir():
        raise DataError(f"synthetic data root {root} exists and is not a directory")
    for name in sequences:
        config.spec(name)  # unknown names fail before any work
    todo = [n for n in dict.fromkeys(sequences) if not is_current(root, n, seed, config, version)]
    if not todo:
        return
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"cannot create synthetic data root {root}: {exc}") from exc
    def cost(n: str) -> int:  # the scans to write
        return 0 if n in STREAMED_SEQUENCES else config.spec(n, version).frames

    todo.sort(key=lambda n: -cost(n))  # longest first balances the threads
    total = sum(cost(n) for n in todo)
    lock = threading.Lock()
    stop = threading.Event()  # set on an interrupt so the worker threads end early
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="scan", desc=f"synth {' '.join(todo)}")

    def tick() -> None:
        if stop.is_set():
            raise KeyboardInterrupt
        if bar is not None:
            with lock:
                bar.update(1)

    try:
        with ThreadPoolExecutor(max_workers=min(WORKERS, len(todo))) as pool:
            futures = [pool.submit(generate_sequence, root, n, seed, config, tick, version) for n in todo]
            try:
                for f in futures:
                    f.result()
            except BaseException:
                stop.set()
                raise
    finally:
        if bar is not None:
            bar.close()


__all__ = ["ALL_SEQUENCES", "Scanner", "check_version", "default_root", "ensure", "generate_sequence",
           "is_current", "is_streamed"]
