"""Exact values of `safl_bench.metrics` on small hand-made cases."""
