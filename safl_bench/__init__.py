"""safl-bench: a Gymnasium-style benchmark for LiDAR loop-closure-detection descriptors."""

from __future__ import annotations

__version__ = "0.1.0"

# Register the built-in tasks (with Gymnasium too, lazily: nothing is loaded until a task is made),
# so that `gymnasium.make("SAFL/Synth00-T1R1-v4")` works after `import safl_bench`.
from safl_bench import tasks as _tasks  # noqa: F401
