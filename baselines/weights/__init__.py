"""Shipped trained weights (`<method name>.safetensors`), found by safl_bench.method_registry."""
