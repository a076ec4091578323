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
* `kind`: "descriptor" (this contract) or "retrieval" (`retrieve` answers each query with
  ranked, verified candidates instead: `safl_bench.methods.retrieval`).

`get_params()`/`set_params()` follow scikit-learn (read from the constructor's signature, so
every constructor argument must be stored as an attribute of the same name). `config()` is the
JSON record of a configured method. `save(path)` / `load(path)` store the learned state as
safetensors with the constructor parameters in the metadata (see `safl_bench.methods.weights`).

The registry lives here too, beside the class it registers: `Method.load` on the base class
looks the saved name up in it and the registry checks classes against `Method`, so the two are
one module (two would import each other). Built-in and third-party methods are found by name;
two ways in, one registry:

* the `@register_method` decorator on a `Method` subclass (the built-ins SAD, BiGAN and
  Stable-AFL use it; their modules are imported on first use of the registry);
* the entry-point group `safl_bench.methods` of any installed distribution, e.g. in the
  plug-in's pyproject.toml::

      [project.entry-points."safl_bench.methods"]
      my_method = "my_package.module:MyMethod"

  The entry point must name a `Method` subclass. A plug-in that fails to import does not break
  the others: it is listed with its error and `make_method` on it raises RegistryError.

`make_method(name, weights=..., **params)` builds a configured instance; `list_methods()` says
what is registered and where each came from (module and distribution).

Several versions of one name may be registered (each its own class): a bare name is the newest
(`version_key`: "10" after "9"), ``name@version`` selects one (`method_class`), and shipped
weights belong to one version (`shipped_weights_path`); docs/guides/add-method.md#versions.
What a bare name RUNS on a data source is `resolve_method`: for a method that learns its
weights, the newest version that ships weights for that source, so a fresh installation scores
trained networks; `make_method` never falls back to untrained ones unless asked
(``weights="untrained"``).
"""

from __future__ import annotations

import difflib
import functools
import importlib
import inspect
import re
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np
import torch

from safl_bench.common.fingerprint import to_jsonable
from safl_bench.errors import ConfigError, DataError, RegistryError
from safl_bench.methods.distance import sqeuclidean

INPUT_KINDS: tuple[str, ...] = ("topview", "points")

#: "descriptor": describe + distance (this module); "retrieval": ranked, verified candidates
#: per query (`safl_bench.methods.retrieval`).
METHOD_KINDS: tuple[str, ...] = ("descriptor", "retrieval")

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
    antialiased; `safl_bench.views.resample.fit_input`), anything else unchanged."""
    if method.input_kind != "topview" or method.input_size is None:
        return views
    from safl_bench.views.resample import fit_input

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
    #: "descriptor" (this contract) or "retrieval" (`safl_bench.methods.retrieval.RetrievalMethod`)
    kind: ClassVar[str] = "descriptor"
    #: True for methods whose `fit` learns something (they also implement the state hooks).
    trainable: ClassVar[bool] = False
    #: Constructor parameters that do not change the outputs (e.g. a batch size for inference);
    #: they may differ from those stored with loaded weights.
    runtime_params: ClassVar[tuple[str, ...]] = ()
    #: Where the learned state came from (set by `load` / `make_method`); recorded in `config()`.
    weights_info: dict[str, Any] | None = None
    #: True for methods slow enough that the harness keeps their descriptors on disk, keyed by
    #: their configuration and each view (`safl_bench.methods.descriptor_cache`).
    cache_descriptors: ClassVar[bool] = False
    #: The top-view encoding the method reads on sources with scans (`MapConfig.encoding`, e.g.
    #: "bev-density" for BEVPlace, whose network learned that image); None: the task's own maps.
    view_encoding: ClassVar[str | None] = None
    #: True when each row of ``distance(queries, database)`` depends on that query and the
    #: database only, so the matcher may compute the difference matrix a block of queries at a
    #: time (`safl_bench.matching.blocks`; `check_method` tests it). Set False for a distance
    #: that looks at all queries at once (one normalised over the queries, say): the matcher
    #: then builds the whole matrix, and says so.
    rowwise_distance: ClassVar[bool] = True

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
        the data it was trained on (`safl_bench.methods.training_data.TrainedOn.to_dict`) when given."""
        from safl_bench.methods.weights import save_tensors

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

        Called on a subclass, the file must be that method's and that version's; called on
        `Method`, the class is found in the registry by the name and version stored in the file
        (the newest version when the saved one is not registered). `overrides` may change only
        `runtime_params` (parameters that do not change the outputs)."""
        from safl_bench.methods.weights import file_sha256, load_tensors

        tensors, meta = load_tensors(path)
        info = meta.get("method") if meta.get("kind") == "method" else None
        if not isinstance(info, dict) or "name" not in info:
            raise DataError(f"{path} does not hold a saved method (a training checkpoint? use its final weights)")
        target: type[Method] = cls
        if cls is Method:
            saved = str(info.get("version") or "")
            known = method_versions(str(info["name"]))
            target = method_class(f"{info['name']}@{saved}" if saved in known else str(info["name"]))
        elif info["name"] != cls.name:
            raise DataError(f"{path} holds weights of method {info['name']!r}, not {cls.name!r}")
        elif info.get("version") and str(info["version"]) != str(cls.version):
            # one version never runs another's weights (their networks and outputs differ)
            raise DataError(f"{path} holds weights of {cls.name}@{info['version']}, not of "
                            f"{cls.name}@{cls.version}; select that version: --method "
                            f"{cls.name}@{info['version']}")
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


# --- the registry ---------------------------------------------------------------------------

ENTRY_POINT_GROUP = "safl_bench.methods"
BUILTIN_MODULES: tuple[str, ...] = (
    "baselines.sad", "baselines.bigan", "baselines.bigan_v2", "methods.stable_afl", "methods.stable_afl_v2",
    "baselines.scan_context", "baselines.m2dp", "baselines.bevplace", "baselines.map_closures",
)
_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9_.\-]*$")


@dataclass(frozen=True)
class MethodInfo:
    """A registered method and its origin."""

    name: str
    version: str
    input_kind: str
    module: str
    distribution: str | None  # "name version" of the installed distribution, if known
    via: str  # "decorator" or "entry point <ep name>"
    cls: type[Method] | None = None
    error: str | None = None  # set for an entry point that failed to load

    @property
    def origin(self) -> str:
        """Human-readable origin: module, distribution and how it registered."""
        dist = self.distribution or "no installed distribution"
        return f"{self.module} ({dist}; {self.via})"

    @property
    def summary(self) -> str:
        """First line of the class docstring."""
        doc = (self.cls.__doc__ or "").strip() if self.cls is not None else ""
        return doc.splitlines()[0] if doc else ""


#: every registered version of every method: name -> version -> info
_versions: dict[str, dict[str, MethodInfo]] = {}
#: the newest version of each name: what a bare name means
_registry: dict[str, MethodInfo] = {}
_broken: dict[str, MethodInfo] = {}
_discovered = False


@functools.cache
def _packages_distributions() -> dict[str, list[str]]:
    """importlib's top-level package -> distributions map, read once (it scans every installed
    distribution's file list: about 0.5 s, which every registered method used to pay)."""
    try:
        return dict(metadata.packages_distributions())
    except Exception:  # pragma: no cover - broken metadata on the path
        return {}


def _distribution_of(module: str) -> str | None:
    top = module.split(".")[0]
    names = _packages_distributions().get(top, [])
    for dist_name in names:
        try:
            return f"{dist_name} {metadata.version(dist_name)}"
        except metadata.PackageNotFoundError:
            continue
    return None


def _validate_class(cls: Any, where: str) -> type[Method]:
    if not (isinstance(cls, type) and issubclass(cls, Method)):
        raise RegistryError(f"{where}: {cls!r} is not a subclass of safl_bench.methods.method.Method")
    if not isinstance(cls.name, str) or not _NAME_RE.match(cls.name):
        raise RegistryError(
            f"{where}: {cls.__name__}.name must be a lowercase id (letters, digits, _ . -), got {cls.name!r}"
        )
    if not isinstance(cls.version, str) or not cls.version:
        raise RegistryError(f"{where}: {cls.__name__}.version must be a non-empty string")
    if cls.input_kind not in INPUT_KINDS:
        raise RegistryError(f"{where}: {cls.__name__}.input_kind must be one of {INPUT_KINDS}, got {cls.input_kind!r}")
    if cls.kind not in METHOD_KINDS:
        raise RegistryError(f"{where}: {cls.__name__}.kind must be one of {METHOD_KINDS}, got {cls.kind!r}")
    return cls


def version_key(version: str) -> tuple[tuple[int, str], ...]:
    """Sort key of a version string: dot-separated parts, numeric ones compared as numbers
    ("10" after "9"), others as text after every number."""
    return tuple((int(p), "") if p.isdigit() else (1 << 62, p) for p in version.split("."))


def _add(cls: type[Method], via: str, distribution: str | None) -> None:
    versions = _versions.setdefault(cls.name, {})
    existing = versions.get(cls.version)
    if existing is not None:
        if existing.cls is cls:
            return
        raise RegistryError(
            f"method {cls.name!r} version {cls.version!r} is taken by {existing.origin}; cannot also "
            f"register {cls.__module__}.{cls.__qualname__} (give it another `version`)"
        )
    versions[cls.version] = MethodInfo(
        name=cls.name,
        version=cls.version,
        input_kind=cls.input_kind,
        module=cls.__module__,
        distribution=distribution,
        via=via,
        cls=cls,
    )
    _registry[cls.name] = versions[max(versions, key=version_key)]


def register_method(cls: type[Method]) -> type[Method]:
    """Class decorator: register a `Method` subclass under its `name`."""
    _validate_class(cls, f"@register_method on {cls!r}")
    _add(cls, "decorator", _distribution_of(cls.__module__))
    return cls


def unregister_method(name: str) -> None:
    """Remove a registered method, every version of it, or one with ``name@version`` (for tests
    and interactive use); RegistryError if unknown."""
    base, _, version = name.partition("@")
    if version:
        if _versions.get(base, {}).pop(version, None) is None:
            raise RegistryError(f"no method {name!r} is registered")
        if _versions[base]:
            _registry[base] = _versions[base][max(_versions[base], key=version_key)]
        else:
            del _versions[base]
            del _registry[base]
        return
    _versions.pop(name, None)
    if _registry.pop(name, None) is None and _broken.pop(name, None) is None:
        raise RegistryError(f"no method {name!r} is registered")


def _load_entry_points() -> None:
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        dist = f"{ep.dist.name} {ep.dist.version}" if ep.dist is not None else None
        where = f"entry point {ep.name!r} = {ep.value!r} ({dist or 'unknown distribution'})"
        try:
            cls = _validate_class(ep.load(), where)
            _add(cls, f"entry point {ep.name}", dist)
        except Exception as exc:
            message = f"{type(exc).__name__}: {exc}"
            warnings.warn(f"safl-bench: skipping method plug-in {where}: {message}", stacklevel=3)
            _broken[ep.name] = MethodInfo(
                name=ep.name, version="?", input_kind="?", module=ep.value, distribution=dist,
                via=f"entry point {ep.name}", error=message,
            )


def discover(refresh: bool = False) -> None:
    """Import the built-in methods and load the entry points (once; `refresh` rescans them)."""
    global _discovered
    if _discovered and not refresh:
        return
    _discovered = True
    for module in BUILTIN_MODULES:
        importlib.import_module(module)
    if refresh:
        importlib.invalidate_caches()
        _packages_distributions.cache_clear()  # a distribution may have been installed since
        _broken.clear()
    _load_entry_points()


def list_methods(*, include_broken: bool = False, all_versions: bool = False) -> list[MethodInfo]:
    """The registered methods, sorted by name: the newest version of each (every version, oldest
    first, with `all_versions`), and failed plug-ins if `include_broken`."""
    discover()
    if all_versions:
        infos = [i for versions in _versions.values() for i in versions.values()]
    else:
        infos = list(_registry.values())
    if include_broken:
        infos += [b for name, b in _broken.items() if name not in _registry]
    return sorted(infos, key=lambda i: (i.name, version_key(i.version)))


def method_versions(name: str) -> list[str]:
    """The registered versions of `name`, oldest first (empty when it is not registered)."""
    discover()
    return sorted(_versions.get(name.partition("@")[0], {}), key=version_key)


def method_class(name: str) -> type[Method]:
    """The class registered as `name` (its newest version) or ``name@version`` (that version:
    records name methods that way); RegistryError (with suggestions) when there is none."""
    discover()
    name, _, version = name.partition("@")
    info = _registry.get(name)
    if info is not None and info.cls is not None:
        if not version:
            return info.cls
        chosen = _versions[name].get(version)
        if chosen is None or chosen.cls is None:
            versions = ", ".join(f"{name}@{v}" for v in method_versions(name))
            raise RegistryError(f"method {name!r} has no version {version!r} here; registered: {versions} "
                                f"(a bare {name!r} is the newest)")
        return chosen.cls
    if name in _broken:
        raise RegistryError(f"method {name!r} failed to load from {_broken[name].origin}: {_broken[name].error}")
    known = sorted(_registry)
    close = difflib.get_close_matches(name, known, n=3, cutoff=0.5)
    hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
    raise RegistryError(f"unknown method {name!r}{hint} (known: {', '.join(known) or 'none'})")


def method_selector(name: str, version: str, source: str | None = None) -> str:
    """What a command takes to select `name` at `version`: the bare name when that is the
    newest registered version and, given the data `source` ("synth", "kitti", "bev"), the one a
    bare name runs there (`resolve_method`), else ``name@version``; commands printed for a
    record (explain, run) use it so that they pick the record's version."""
    versions = method_versions(name)
    if not versions or versions[-1] != str(version):
        return f"{name}@{version}"
    if source is not None and resolve_method(name, source) != f"{name}@{version}":
        return f"{name}@{version}"
    return name


#: How messages name each data source kind, and the option `safl-bench train` takes for it.
SOURCE_WORDS: dict[str, tuple[str, str]] = {
    "synth": ("the synthetic default", ""),
    "kitti": ("KITTI scans", " --kitti-root DIR"),
    "bev": ("top-view images", " --bev-root DIR"),
}


def trained_versions(name: str, source: str | None = None) -> list[str]:
    """The registered versions of `name` (bare) that learn their weights and ship weights for
    `source` (`shipped_weights_path`; None: the synthetic default's), oldest first."""
    base = name.partition("@")[0]
    out = []
    for version in method_versions(base):
        cls = method_class(f"{base}@{version}")
        if cls.trainable and shipped_weights_path(cls, source) is not None:
            out.append(version)
    return out


def resolve_method(name: str, source: str | None = None, weights: str | Path | None = None) -> str:
    """``name@version``: the version `name` runs on data `source` ("synth", the default when
    None; "kitti"; "bev"). ``name@version`` is itself; a bare name of a method that learns its
    weights is the version of the weights file `weights` when it names one, else the newest
    version that ships weights for `source` (`trained_versions`), else the newest; a bare name
    of any other method is its newest version. It depends only on the registry, the shipped
    files and the file given, and records hold the version it picked."""
    cls = method_class(name)  # an unknown name or version fails here
    if "@" in name or not cls.trainable:
        return f"{cls.name}@{cls.version}"
    if weights not in (None, "shipped", "untrained"):
        saved = _saved_version(Path(str(weights)))
        if saved is not None and saved in method_versions(name):
            return f"{cls.name}@{saved}"
    trained = trained_versions(name, source)
    return f"{cls.name}@{trained[-1] if trained else cls.version}"


def missing_weights_message(cls: type[Method], source: str | None = None) -> str:
    """The one line for a version of a learned method that ships no weights for `source`: the
    versions that do, and the commands that make its own or score it untrained."""
    kind = source or "synth"
    where, option = SOURCE_WORDS.get(kind, (f"source {kind!r}", ""))
    selector = f"{cls.name}@{cls.version}"
    have = trained_versions(cls.name, source)
    if have:
        bare = resolve_method(cls.name, source)
        others = (f"versions with weights for it: {', '.join(f'{cls.name}@{v}' for v in have)} "
                  f"(a bare {cls.name!r} runs {bare} there)")
    else:
        others = f"no version of {cls.name!r} ships weights for it"
    return (f"{selector} has no weights for {where}; {others}; make {selector}'s with "
            f"`safl-bench train --method {selector}{option}` and pass the {cls.name}.safetensors "
            "it writes with --weights, or score its untrained networks with --weights untrained")


def _ships_weights(cls: type[Method]) -> bool:
    """A method that is not trained here but runs published weights shipped with it (class
    attribute `ships_weights = True`; its constructor loads them)."""
    return bool(getattr(cls, "ships_weights", False))


def shipped_weights_path(cls: type[Method], source: str | None = None) -> Path | None:
    """The weights file shipped beside the method's module for this version of it:
    `weights/<name>-v<version>-<source>.safetensors` (trained on that kind of data, e.g. "bev":
    real KITTI top views) when `source` is given and there is one, else
    `weights/<name>-v<version>.safetensors` (the synthetic default's). The unversioned names
    `<name>-<source>` / `<name>` (the files of the first releases) count only when the version
    saved in them is this class's, so one version never runs another's weights. None when this
    version ships none (yet)."""
    module = sys.modules.get(cls.__module__)
    file = getattr(module, "__file__", None)
    if not (cls.trainable or _ships_weights(cls)) or file is None:
        return None
    folder = Path(file).parent / "weights"
    kinds = ([f"-{source}"] if source else []) + [""]
    for kind in kinds:
        versioned = folder / f"{cls.name}-v{cls.version}{kind}.safetensors"
        if versioned.is_file():
            return versioned
        legacy = folder / f"{cls.name}{kind}.safetensors"
        if legacy.is_file() and _saved_version(legacy) == str(cls.version):
            return legacy
    return None


def _saved_version(path: Path) -> str | None:
    """The method version stored in a weights file's metadata (only the header is read)."""
    import json

    from safetensors import safe_open

    from safl_bench.methods.weights import METADATA_KEY

    try:
        with safe_open(str(path), framework="pt", device="cpu") as fh:
            meta = json.loads((fh.metadata() or {}).get(METADATA_KEY, "{}"))
    except Exception:  # an unreadable file is reported when it is loaded
        return None
    info = meta.get("method") if isinstance(meta, dict) else None
    return str(info.get("version")) if isinstance(info, dict) else None


def make_method(name: str, *, weights: str | Path | None = None, source: str | None = None,
                **params: Any) -> Method:
    """A configured instance of the method registered as `name` or ``name@version`` (that
    version; an unregistered one is a RegistryError listing them). A bare name is the version
    it runs on `source` (`resolve_method`: for a learned method, the newest version with weights
    for that source, or the version of the weights file given).

    For trainable methods, `weights` picks the learned state (`config()["weights"]` records it):
      * None (default) or "shipped": the shipped weights (those trained on `source`'s kind of
        data where they exist, see `shipped_weights_path`); a version that ships none for
        `source` is a ConfigError naming the versions that do and the `safl-bench train`
        command that makes its own (`missing_weights_message`), never untrained networks;
      * "untrained": the randomly initialised networks (the honesty baseline), only when asked;
        recorded as ``{"source": "untrained", "seed": ...}``;
      * a path: a file written by `Method.save` / `safl-bench train`.

    Methods with published weights that are not trained here (`ships_weights`, e.g. BEVPlace)
    load the shipped ones in their constructor (None or "shipped"); a path goes to `cls.load`;
    they have no "untrained" variant.
    """
    cls = method_class(resolve_method(name, source, weights))
    if not cls.trainable and _ships_weights(cls):
        if weights == "untrained":
            raise ConfigError(f"method {name!r} runs its authors' published weights; it has no untrained variant")
        if weights is None or weights == "shipped":
            return _construct(cls, params)
        return cls.load(Path(weights), **params)
    if not cls.trainable:
        if weights not in (None, "untrained"):
            raise ConfigError(f"method {name!r} learns nothing and takes no weights (got {weights!r})")
        return _construct(cls, params)
    if weights is None or weights == "shipped":
        shipped = shipped_weights_path(cls, source)
        if shipped is not None:
            method = cls.load(shipped, **params)
            # records name the shipped file by package, not by this machine's install path
            method.weights_info = {
                **(method.weights_info or {}),
                "source": "shipped",
                "path": f"{cls.__module__.rsplit('.', 1)[0]}/weights/{shipped.name}",
                "picked_for": source or "synth",
            }
            return method
        raise ConfigError(missing_weights_message(cls, source))
    if weights == "untrained":
        method = _construct(cls, params)
        method.weights_info = {"source": "untrained", "seed": params.get("seed", getattr(method, "seed", None))}
        return method
    return cls.load(Path(weights), **params)


def _construct(cls: type[Method], params: dict[str, Any]) -> Method:
    valid = set(cls._param_names())
    unknown = sorted(set(params) - valid)
    if unknown:
        raise ConfigError(f"method {cls.name!r} has no parameter(s) {unknown}; valid: {sorted(valid)}")
    return cls(**params)
