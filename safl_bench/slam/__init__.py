"""Loop closure in SLAM: what a cell's accepted matches do to a robot's trajectory.

A (method, revisit task, seed) cell's per-query matches, read from its result record (no
descriptor is recomputed), become loop-closure factors of a 2-D pose graph over the task's frames,
with odometry factors from the ground-truth motion plus seeded drift (`model`); GTSAM solves it
with least squares, a robust kernel and graduated non-convexity, and evo measures the optimised
trajectories against the truth (`backend`); `cell` ties a record and its task to that. The
modelling choices and their sources: docs/reference/slam-stage.md (how to run it: docs/guides/slam.md).
"""
