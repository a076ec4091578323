"""Exact values of `safl_bench.evaluation` on small hand-made cases."""
