"""Exact values of `safl_bench.groundtruth` on small hand-made cases."""
