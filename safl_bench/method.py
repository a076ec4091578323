"""The descriptor-method plug-in interface, modelled on scikit-learn estimators.

A method turns views of places into descriptors::

    method = MyMethod(param=...)          # constructor arguments ARE the configuration
    method.fit(maps)                      # unlabelled training views; a no-op for hand-crafted ones
    d = method.describe(maps)             # (N, D) float32
    D = method.distance(d_query, d_db)    # (Nq, Ndb), lower = more similar; default Eq. 4

Class attributes say what the harness must know without running anything:

* `name`, `version`: go into every result record (bump `version` when outputs change);
* `input_kind`: which view the method reads. "topview": an (N, H, W) float32 array of top-view
  maps in [0, 1]; "points": a list of (M_i, 3) float32 arrays, the local-map points in each
  viewpoint's frame, inside the top view's window (the same part of the map the top view shows). The harness asks the map cache for `method.input_kind` and hands the result
  to `fit`/`describe` unchanged; nothing is special-cased per method.

`get_params()`/`set_params()` follow scikit-learn (read from the constructor's signature, so
every constructor argument must be stored as an attribute of the same name). `config()` is the
JSON record of a configured method. `save(path)` / `load(path)` store the learned state as
safetensors with the constructor parameters in the metadata (see `safl_bench.weights`).
"""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np
import torch

from safl_bench.distance import sqeuclidean
from safl_bench.errors import ConfigError, DataError
from safl_bench.fingerprint import to_jsonable

INPUT_KINDS: tuple[str, ...] = ("topview", "points")

Views = np.ndarray | Sequence[np.ndarray]


def as_topview(maps: Any, *, what: str = "maps") -> np.ndarray:
    """Validate top-view maps: (N, H, W), finite, in [0, 1]; returns a float32 array (no copy
    when it already is one). Raises DataError naming the problem."""
    arr = np.asarray(maps)
    if arr.ndim == 2:
        raise DataError(f"{what}: expected a batch (N, H, W) of top-view maps, got one map {arr.shape}; use maps[None]")
    if arr.ndim != 3:
        raise DataError(f"{what}: expected shape (N, H, W), got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.floating) and not np.issubdtype(arr.dtype, np.integer):
        raise DataError(f"{what}: expected a numeric array, got dtype {arr.dtype}")
    arr = arr.astype(np.float32, copy=False)
    if arr.size:
        lo, hi = float(arr.min()), float(arr.max())  # NaN propagates into both
        if np.isnan(lo) or np.isnan(hi):
            raise DataError(f"{what}: contains NaN")
        if not (lo >= -1e-6 and hi <= 1 + 1e-6):
            raise DataError(f"{what}: values must lie in [0, 1], got [{lo:g}, {hi:g}]")
    return arr


def as_points(views: Any, *, what: str = "views") -> list[np.ndarray]:
    """Validate point views: a sequence of (M_i, 3) finite float arrays; returns float32 arrays."""
    if isinstance(views, np.ndarray) and views.dtype != object:
        raise DataError(f"{what}: expected a list of (M, 3) point arrays, got one array {views.shape}")
    out = []
    for i, v in enumerate(views):
        a = np.asarray(v, dtype=np.float32)
        if a.ndim != 2 or a.shape[1] != 3:
            raise DataError(f"{what}[{i}]: expected shape (M, 3), got {a.shape}")
        if not np.isfinite(a).all():
            raise DataError(f"{what}[{i}]: contains NaN or inf")
        out.append(a)
    return out


def method_input(method: Method, views: Any) -> Any:
    """`views` as `method` takes them: top views resampled to its `input_size` (bilinear,
    antialiased; `safl_bench.resample.fit_input`), anything else unchanged."""
    if method.input_kind != "topview" or method.input_size is None:
        return views
    from safl_bench.resample import fit_input

    return fit_input(np.asarray(views), method.input_size)


def input_note(method: Method, views: Any) -> str | None:
    """What `method_input` does to `views`, for records (None when it changes nothing)."""
    size = method.input_size if method.input_kind == "topview" else None
    if size is None:  # any size, or point views (a list of arrays of different lengths)
        return None
    shape = np.shape(views)[1:]
    if shape == (size, size):
        return None
    return f"{shape[0]}x{shape[1]} views resampled to {size}x{size} (bilinear, antialiased)"


class Method:
    """Base class of descriptor methods. Subclass, set `name`/`version`, implement `describe`."""

    name: ClassVar[str] = ""
    version: ClassVar[str] = ""
    input_kind: ClassVar[str] = "topview"
    #: True for methods whose `fit` learns something (they also implement the state hooks).
    trainable: ClassVar[bool] = False
    #: Constructor parameters that do not change the outputs (e.g. a batch size for inference);
    #: they may differ from those stored with loaded weights.
    runtime_params: ClassVar[tuple[str, ...]] = ()
    #: Where the learned state came from (set by `load` / `make_method`); recorded in `config()`.
    weights_info: dict[str, Any] | None = None
    #: True for methods slow enough that the harness keeps their descriptors on disk, keyed by
    #: their configuration and each view (`safl_bench.descriptor_cache`).
    cache_descriptors: ClassVar[bool] = False
    #: The top-view encoding the method reads on sources with scans (`MapConfig.encoding`, e.g.
    #: "bev-density" for BEVPlace, whose network learned that image); None: the task's own maps.
    view_encoding: ClassVar[str | None] = None

    @property
    def input_size(self) -> int | None:
        """Side of the square top view the method takes, None for any size: the harness resamples
        views of another size to it (`method_input`) and records that it did."""
        return None

    # -- the contract ---------------------------------------------------------------------------
    def fit(self, maps: Views) -> Self:
        """Learn from unlabelled views. Hand-crafted methods keep this no-op. Returns self."""
        return self

    def describe(self, maps: Views) -> np.ndarray:
        """Descriptors of the views: (N, D) float32, row i for view i, independent of the batch."""
        raise NotImplementedError(f"{type(self).__name__} must implement describe()")

    def distance(self, queries: np.ndarray, database: np.ndarray) -> np.ndarray:
        """Difference matrix (Nq, Ndb), lower = more similar. Default: Eq. 4, squared Euclidean."""
        return sqeuclidean(queries, database)

    # -- configuration (scikit-learn style) ----------------------------------------------------
    @classmethod
    def _param_names(cls) -> list[str]:
        init = cls.__init__
        if init is object.__init__:
            return []
        sig = inspect.signature(init)
        names = []
        for p in sig.parameters.values():
            if p.name == "self":
                continue
            if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
                raise TypeError(f"{cls.__name__}.__init__ must not take *args/**kwargs (scikit-learn rule)")
            names.append(p.name)
        return sorted(names)

    def get_params(self, deep: bool = False) -> dict[str, Any]:
        """The constructor arguments of this instance."""
        return {n: getattr(self, n) for n in self._param_names()}

    def set_params(self, **params: Any) -> Self:
        """Change constructor arguments in place (scikit-learn style); unknown names: ConfigError."""
        valid = set(self._param_names())
        for key, value in params.items():
            if key not in valid:
                raise ConfigError(f"{self.name or type(self).__name__} has no parameter {key!r}; valid: {sorted(valid)}")
            setattr(self, key, value)
        return self

    def config(self) -> dict[str, Any]:
        """JSON record of this configured method (goes into every result)."""
        record: dict[str, Any] = {
            "name": self.name,
            "version": self.version,
            "input_kind": self.input_kind,
            "class": f"{type(self).__module__}.{type(self).__qualname__}",
            "params": to_jsonable(self.get_params()),
        }
        weights = getattr(self, "weights_info", None)
        if weights is not None:
            record["weights"] = to_jsonable(weights)
        return record

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"{type(self).__name__}({args})"

    # -- learned state -------------------------------------------------------------------------
    def state_tensors(self, parts: Sequence[str] | None = None) -> dict[str, torch.Tensor]:
        """Learned state as named tensors (`parts` selects a subset, e.g. only the encoder)."""
        return {}

    def load_state_tensors(self, tensors: dict[str, torch.Tensor], *, source: str) -> None:
        """Inverse of `state_tensors`."""
        if tensors:
            raise DataError(f"{source}: {self.name} has no learned state but the file holds tensors")

    def save(self, path: str | Path, *, parts: Sequence[str] | None = None,
             trained_on: dict[str, Any] | None = None) -> Path:
        """Write the learned state and the constructor parameters to a safetensors file, with
        the data it was trained on (`safl_bench.training_data.TrainedOn.to_dict`) when given."""
        from safl_bench.weights import save_tensors

        record = self.config()
        record.pop("weights", None)
        meta = {"kind": "method", "method": record, "parts": list(parts) if parts else None}
        if trained_on is not None:
            meta["trained_on"] = trained_on
        save_tensors(path, self.state_tensors(parts), meta)
        return Path(path)

    @classmethod
    def load(cls, path: str | Path, **overrides: Any) -> Method:
        """Build a method from a file written by `save` (safetensors only; no code runs).

        Called on a subclass, the file must be that method's; called on `Method`, the class is
        found in the registry by the name stored in the file. `overrides` may change only
        `runtime_params` (parameters that do not change the outputs)."""
        from safl_bench.weights import file_sha256, load_tensors

        tensors, meta = load_tensors(path)
        info = meta.get("method") if meta.get("kind") == "method" else None
        if not isinstance(info, dict) or "name" not in info:
            raise DataError(f"{path} does not hold a saved method (a training checkpoint? use its final weights)")
        target: type[Method] = cls
        if cls is Method:
            from safl_bench.method_registry import method_class

            target = method_class(info["name"])
        elif info["name"] != cls.name:
            raise DataError(f"{path} holds weights of method {info['name']!r}, not {cls.name!r}")
        params = dict(info.get("params", {}))
        for key, value in overrides.items():
            if key in params and params[key] != value and key not in target.runtime_params:
                raise ConfigError(
                    f"{key}={value!r} conflicts with the weights in {path} (trained with {key}={params[key]!r})"
                )
            params[key] = value
        try:
            method = target(**params)
        except TypeError as exc:
            raise DataError(f"{path}: its parameters do not fit {target.__name__}: {exc}") from exc
        method.load_state_tensors(tensors, source=str(path))
        method.weights_info = {
            "source": "file",
            "path": str(path),
            "sha256": file_sha256(path),
            "saved_version": info.get("version"),
            "parts": meta.get("parts"),
        }
        if isinstance(meta.get("trained_on"), dict):
            method.weights_info["trained_on"] = meta["trained_on"]
        return method
