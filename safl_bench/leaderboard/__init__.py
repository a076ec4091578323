"""The leaderboard: tables and figures regenerated from result records.

`build_leaderboard(records, out_dir, ...)` writes everything; the pieces live in `grouping`
(which records share a table, how seeds combine), `tables` (Markdown/CSV), `figures` (PNG) and
`training_logs` (the logs behind the training-stability figure).
"""

from safl_bench.leaderboard.build import build_leaderboard
from safl_bench.leaderboard.report import BuildReport

__all__ = ["BuildReport", "build_leaderboard"]
