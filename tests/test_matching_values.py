"""Exact values of `safl_bench.matching` on small hand-made cases."""
