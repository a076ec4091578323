"""Stage 6, results: one JSON record per (method, task, seed) cell (`records`, typed models with
a published JSON Schema) and where each came from (`provenance`: versions, hardware, git).
"""
