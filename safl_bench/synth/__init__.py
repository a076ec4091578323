"""The embedded default dataset: a synthetic town scanned by a simulated 64-beam LiDAR.

Written in exactly the KITTI odometry layout, so the same reader, map builder and tasks run on it.

    from safl_bench import synth
    synth.ensure(synth.default_root(), synth.TEST_SEQUENCES)  # generates what is missing

Modules: `streets` (street grid and warp), `world` (town raster), `routes` (routes that revisit
places, vehicle poses), `lidar` (sensor model and ray casting), `writer` (KITTI files),
`generate` (ensure / manifests), `config` (SynthConfig, sequence names).
"""

from safl_bench.synth.config import (
    ALL_SEQUENCES,
    DEFAULT_SEED,
    GENERATOR_VERSION,
    GENERATOR_VERSIONS,
    KNOWN_SEQUENCES,
    STREAMED_SEQUENCES,
    TEST_SEQUENCES,
    TRAIN_SEQUENCES,
    SynthConfig,
)
from safl_bench.synth.generate import (
    Scanner,
    check_version,
    default_root,
    ensure,
    generate_sequence,
    is_current,
    is_streamed,
    make_route,
    make_scene_world,
)

__all__ = [
    "ALL_SEQUENCES",
    "DEFAULT_SEED",
    "GENERATOR_VERSION",
    "GENERATOR_VERSIONS",
    "KNOWN_SEQUENCES",
    "STREAMED_SEQUENCES",
    "TEST_SEQUENCES",
    "TRAIN_SEQUENCES",
    "Scanner",
    "SynthConfig",
    "check_version",
    "default_root",
    "ensure",
    "generate_sequence",
    "is_current",
    "is_streamed",
    "make_route",
    "make_scene_world",
]
