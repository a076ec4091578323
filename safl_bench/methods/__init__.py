"""Stage 3, methods: the descriptor plug-in interface and what serves it.

`method` (the `Method` base class and the registry of methods by name, with the entry-point
group ``safl_bench.methods``), `check` (the conformance check of a plug-in), `weights`
(safetensors files of learned state), `training_data` (which data weights were trained on and
whether a record's task is among them), `descriptor_cache` (descriptors kept on disk), `training`
(the training loop of learned methods) and `distance` (the difference matrix of Eq. 4, every
method's default `Method.distance`).

The methods themselves are plug-ins outside this package: the paper's Stable-AFL in the
top-level package `methods`, the baselines in `baselines`.
"""
