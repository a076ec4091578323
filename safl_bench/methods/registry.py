"""The method registry: built-in and third-party descriptor methods, found by name.

Two ways in, one registry:

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
"""

from __future__ import annotations

import difflib
import importlib
import re
import sys
import warnings
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

from safl_bench.errors import ConfigError, RegistryError
from safl_bench.method import INPUT_KINDS, Method

ENTRY_POINT_GROUP = "safl_bench.methods"
BUILTIN_MODULES: tuple[str, ...] = (
    "baselines.sad", "baselines.bigan", "methods.stable_afl", "baselines.scan_context", "baselines.m2dp",
    "baselines.bevplace",
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


_registry: dict[str, MethodInfo] = {}
_broken: dict[str, MethodInfo] = {}
_discovered = False


def _distribution_of(module: str) -> str | None:
    top = module.split(".")[0]
    try:
        names = metadata.packages_distributions().get(top, [])
    except Exception:  # pragma: no cover - broken metadata on the path
        return None
    for dist_name in names:
        try:
            return f"{dist_name} {metadata.version(dist_name)}"
        except metadata.PackageNotFoundError:
            continue
    return None


def _validate_class(cls: Any, where: str) -> type[Method]:
    if not (isinstance(cls, type) and issubclass(cls, Method)):
        raise RegistryError(f"{where}: {cls!r} is not a subclass of safl_bench.method.Method")
    if not isinstance(cls.name, str) or not _NAME_RE.match(cls.name):
        raise RegistryError(
            f"{where}: {cls.__name__}.name must be a lowercase id (letters, digits, _ . -), got {cls.name!r}"
        )
    if not isinstance(cls.version, str) or not cls.version:
        raise RegistryError(f"{where}: {cls.__name__}.version must be a non-empty string")
    if cls.input_kind not in INPUT_KINDS:
        raise RegistryError(f"{where}: {cls.__name__}.input_kind must be one of {INPUT_KINDS}, got {cls.input_kind!r}")
    return cls


def _add(cls: type[Method], via: str, distribution: str | None) -> None:
    existing = _registry.get(cls.name)
    if existing is not None:
        if existing.cls is cls:
            return
        raise RegistryError(
            f"method name {cls.name!r} is taken by {existing.origin}; cannot also register {cls.__module__}.{cls.__qualname__}"
        )
    _registry[cls.name] = MethodInfo(
        name=cls.name,
        version=cls.version,
        input_kind=cls.input_kind,
        module=cls.__module__,
        distribution=distribution,
        via=via,
        cls=cls,
    )


def register_method(cls: type[Method]) -> type[Method]:
    """Class decorator: register a `Method` subclass under its `name`."""
    _validate_class(cls, f"@register_method on {cls!r}")
    _add(cls, "decorator", _distribution_of(cls.__module__))
    return cls


def unregister_method(name: str) -> None:
    """Remove a registered method (for tests and interactive use); RegistryError if unknown."""
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
        _broken.clear()
    _load_entry_points()


def list_methods(*, include_broken: bool = False) -> list[MethodInfo]:
    """All registered methods, sorted by name (and failed plug-ins if `include_broken`)."""
    discover()
    infos = list(_registry.values())
    if include_broken:
        infos += [b for name, b in _broken.items() if name not in _registry]
    return sorted(infos, key=lambda i: i.name)


def method_class(name: str) -> type[Method]:
    """The class registered as `name` (or ``name@version``, which must be the registered
    version: records name methods that way); RegistryError (with suggestions) when there is
    none."""
    discover()
    name, _, version = name.partition("@")
    info = _registry.get(name)
    if info is not None and info.cls is not None:
        if version and version != str(info.cls.version):
            raise RegistryError(f"method {name!r} is version {info.cls.version} here, not "
                                f"{version!r}; run `{name}` (its only registered version)")
        return info.cls
    if name in _broken:
        raise RegistryError(f"method {name!r} failed to load from {_broken[name].origin}: {_broken[name].error}")
    known = sorted(_registry)
    close = difflib.get_close_matches(name, known, n=3, cutoff=0.5)
    hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
    raise RegistryError(f"unknown method {name!r}{hint} (known: {', '.join(known) or 'none'})")


def _ships_weights(cls: type[Method]) -> bool:
    """A method that is not trained here but runs published weights shipped with it (class
    attribute `ships_weights = True`; its constructor loads them)."""
    return bool(getattr(cls, "ships_weights", False))


def shipped_weights_path(cls: type[Method], source: str | None = None) -> Path | None:
    """The weights file shipped beside the method's module: `weights/<name>-<source>.safetensors`
    (trained on that kind of data, e.g. "bev": real KITTI top views) when `source` is given and
    there is one, else `weights/<name>.safetensors` (the synthetic default's); None when the
    method ships none (yet)."""
    module = sys.modules.get(cls.__module__)
    file = getattr(module, "__file__", None)
    if not (cls.trainable or _ships_weights(cls)) or file is None:
        return None
    folder = Path(file).parent / "weights"
    names = ([f"{cls.name}-{source}.safetensors"] if source else []) + [f"{cls.name}.safetensors"]
    return next((folder / n for n in names if (folder / n).is_file()), None)


def make_method(name: str, *, weights: str | Path | None = None, source: str | None = None,
                **params: Any) -> Method:
    """A configured instance of the method registered as `name`.

    For trainable methods, `weights` picks the learned state:
      * None (default): the shipped weights when the package has them (those trained on
        `source`'s kind of data where they exist, see `shipped_weights_path`), otherwise the
        untrained (random, seeded) networks with a warning; `config()["weights"]` records which;
      * "shipped": the shipped weights, ConfigError when there are none;
      * "untrained": the randomly initialised networks (the honesty baseline);
      * a path: a file written by `Method.save` / `safl-bench train`.

    Methods with published weights that are not trained here (`ships_weights`, e.g. BEVPlace)
    load the shipped ones in their constructor (None or "shipped"); a path goes to `cls.load`;
    they have no "untrained" variant.
    """
    cls = method_class(name)
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
        if weights == "shipped":
            raise ConfigError(
                f"method {name!r} has no shipped weights in this installation; train them with "
                f"`safl-bench train --method {name}` and pass the file with --weights"
            )
        warnings.warn(
            f"method {name!r}: no shipped weights found; using the UNTRAINED (random) networks",
            stacklevel=2,
        )
        weights = "untrained"
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
