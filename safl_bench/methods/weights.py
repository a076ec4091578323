"""Saving and loading network weights and optimizer state as safetensors, never executing code.

A weights file is a plain safetensors file: named tensors plus one metadata entry,
`"safl_bench"`, a JSON string (method name, version, constructor parameters, training epoch,
optimizer scalars...). Reading it goes through `safetensors` only, so a file from an untrusted
source can at worst hold wrong numbers, never run code (unlike pickle / `torch.load`).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors import safe_open
from safetensors.torch import save_file

from safl_bench.common.atomic import atomic_write_with
from safl_bench.common.fingerprint import to_jsonable
from safl_bench.errors import DataError

METADATA_KEY = "safl_bench"

PathLike = str | os.PathLike[str]


def save_tensors(
    path: PathLike,
    tensors: Mapping[str, torch.Tensor | np.ndarray],
    metadata: Mapping[str, Any],
) -> None:
    """Write `tensors` and the JSON-able `metadata` to `path` atomically (safetensors)."""
    plain: dict[str, torch.Tensor] = {}
    for key, value in tensors.items():
        tensor = torch.from_numpy(np.asarray(value)) if isinstance(value, np.ndarray) else value
        plain[key] = tensor.detach().to("cpu").contiguous().clone()
    blob = json.dumps(to_jsonable(dict(metadata)), sort_keys=True, allow_nan=False)
    atomic_write_with(path, lambda tmp: save_file(plain, str(tmp), metadata={METADATA_KEY: blob}))


def load_tensors(path: PathLike) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Read a file written by `save_tensors`: (tensors, metadata). DataError if it is not one."""
    p = Path(path)
    if not p.is_file():
        raise DataError(f"weights file {p} does not exist")
    try:
        with safe_open(str(p), framework="pt", device="cpu") as fh:
            raw_meta = fh.metadata() or {}
            tensors = {key: fh.get_tensor(key) for key in fh.keys()}
    except Exception as exc:  # safetensors raises its own error types for malformed headers
        raise DataError(f"{p} is not a readable safetensors file: {exc}") from exc
    if METADATA_KEY not in raw_meta:
        raise DataError(f"{p} is a safetensors file but was not written by safl-bench")
    try:
        metadata = json.loads(raw_meta[METADATA_KEY])
    except json.JSONDecodeError as exc:
        raise DataError(f"{p}: malformed safl-bench metadata: {exc}") from exc
    if not isinstance(metadata, dict):
        raise DataError(f"{p}: malformed safl-bench metadata (not a JSON object)")
    return tensors, metadata


def file_sha256(path: PathLike) -> str:
    """Hex SHA-256 of a file (recorded with results so a result names the exact weights)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def module_tensors(modules: Mapping[str, torch.nn.Module], prefix: str = "net") -> dict[str, torch.Tensor]:
    """Parameters and buffers of named modules, keyed `prefix/<module>/<state key>`."""
    out: dict[str, torch.Tensor] = {}
    for name, module in modules.items():
        for key, value in module.state_dict().items():
            out[f"{prefix}/{name}/{key}"] = value
    return out


def load_module_tensors(
    modules: Mapping[str, torch.nn.Module],
    tensors: Mapping[str, torch.Tensor],
    *,
    source: PathLike,
    prefix: str = "net",
) -> None:
    """Load `module_tensors` output back into the modules (strict: every key must match)."""
    for name, module in modules.items():
        head = f"{prefix}/{name}/"
        state = {k[len(head) :]: v for k, v in tensors.items() if k.startswith(head)}
        if not state:
            raise DataError(f"{source} holds no weights for network {name!r}")
        try:
            module.load_state_dict(state, strict=True)
        except RuntimeError as exc:
            first = str(exc).strip().splitlines()[0]
            raise DataError(f"{source}: weights of {name!r} do not fit the network: {first}") from exc


def optimizer_tensors(
    optimizers: Mapping[str, torch.optim.Optimizer], prefix: str = "opt"
) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Flatten optimizer states: tensors keyed `prefix/<opt>/<param index>/<key>`, and the JSON
    rest (param groups, non-tensor per-parameter values) to store in the metadata."""
    tensors: dict[str, torch.Tensor] = {}
    scalars: dict[str, Any] = {}
    for name, opt in optimizers.items():
        state = opt.state_dict()
        extra: dict[str, dict[str, Any]] = {}
        for index, per_param in state["state"].items():
            for key, value in per_param.items():
                if isinstance(value, torch.Tensor):
                    tensors[f"{prefix}/{name}/{index}/{key}"] = value
                else:
                    extra.setdefault(str(index), {})[key] = value
        scalars[name] = {"param_groups": state["param_groups"], "extra": extra}
    return tensors, scalars


def load_optimizer_tensors(
    optimizers: Mapping[str, torch.optim.Optimizer],
    tensors: Mapping[str, torch.Tensor],
    scalars: Mapping[str, Any],
    *,
    source: PathLike,
    prefix: str = "opt",
) -> None:
    """Inverse of `optimizer_tensors`."""
    for name, opt in optimizers.items():
        if name not in scalars:
            raise DataError(f"{source} holds no state for optimizer {name!r}")
        per_param: dict[int, dict[str, Any]] = {}
        head = f"{prefix}/{name}/"
        for key, value in tensors.items():
            if key.startswith(head):
                index, sub = key[len(head) :].split("/", 1)
                per_param.setdefault(int(index), {})[sub] = value
        for index, values in scalars[name].get("extra", {}).items():
            per_param.setdefault(int(index), {}).update(values)
        try:
            opt.load_state_dict({"state": per_param, "param_groups": scalars[name]["param_groups"]})
        except (ValueError, KeyError, RuntimeError) as exc:
            raise DataError(f"{source}: optimizer state {name!r} does not fit: {exc}") from exc
