"""safl-bench: a Gymnasium-style benchmark for LiDAR loop-closure-detection descriptors."""

from __future__ import annotations

__version__ = "0.1.0"
