"""Shipped trained weights (`<method name>.safetensors`), found by safl_bench.methods.method."""
