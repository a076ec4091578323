"""The clock: descriptor time per frame, batched throughput, matcher time, peak memory, and the
environment each figure was taken in.

Every figure is the median of `repeats` timed runs after `warmup` untimed ones
(time.perf_counter), with the process CPU time beside it and the load average in the environment:
on a shared machine wall time grows with other people's work, CPU time much less. A "method" is anything with ``describe(maps) -> (N, D)``.

Peak memory is the process's resident set size (RSS), which sees numpy, numba and torch CPU
allocations alike (tracemalloc would miss torch's and numba's): the kernel's high-water mark
(VmHWM) is reset through /proc/self/clear_refs before the call where Linux allows it, and the
figure is the peak minus the RSS just before the call. Where the reset is not possible the
high-water mark only moves if the call exceeds every earlier peak, so the figure is a lower
bound; `memory_method` says which applied ("vmhwm-reset", "vmhwm-lower-bound", "unavailable").
"""

from __future__ import annotations

import os
import platform
import statistics
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import numpy as np

from safl_bench.errors import ConfigError, DataError
from safl_bench.results import provenance


class Describes(Protocol):
    def describe(self, maps: Any) -> np.ndarray: ...


# --------------------------------------------------------------------------- environment

_THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                "NUMBA_NUM_THREADS", "NUMBA_THREADING_LAYER")
_LIBRARIES = ("numpy", "scipy", "scikit-learn", "numba", "torch", "safl-bench")


@dataclass
class Environment:
    """Where a figure was measured."""

    cpu_model: str
    logical_cpus: int
    usable_cpus: int
    machine: str
    system: str
    python: str
    torch_threads: int | None
    numba_threads: int | None
    thread_env: dict[str, str]
    versions: dict[str, str]
    load_avg_1m: float | None  # other work on the machine inflates wall times


def environment() -> Environment:
    """Where a figure is being measured: `provenance`'s hardware and versions, plus the thread
    settings and the load that timings depend on."""
    numba_threads = None
    try:
        import numba

        numba_threads = int(numba.get_num_threads())
    except ImportError:  # pragma: no cover - numba is a dependency
        pass
    return Environment(
        cpu_model=provenance.cpu_model(), logical_cpus=os.cpu_count() or 0,
        usable_cpus=provenance.cpu_cores(),
        machine=platform.machine(), system=f"{platform.system()} {platform.release()}",
        python=platform.python_version(), torch_threads=provenance.torch_threads(),
        numba_threads=numba_threads,
        thread_env={k: os.environ[k] for k in _THREAD_VARS if k in os.environ},
        versions=provenance.library_versions(_LIBRARIES),
        load_avg_1m=os.getloadavg()[0] if hasattr(os, "getloadavg") else None)


# --------------------------------------------------------------------------- pinning


def _threads() -> int:
    """Threads the numeric libraries of this process may use at once (torch, numba)."""
    counts = [provenance.torch_threads() or 1]
    numba = sys.modules.get("numba")
    if numba is not None:
        counts.append(int(numba.get_num_threads()))
    return max(counts)


def _cpu_list(cpus: Sequence[int]) -> str:
    """'CPU 3', 'CPUs 0-3' or 'CPUs 0,2,5'."""
    ordered = sorted(cpus)
    if len(ordered) == 1:
        return f"CPU {ordered[0]}"
    if ordered == list(range(ordered[0], ordered[-1] + 1)):
        return f"CPUs {ordered[0]}-{ordered[-1]}"
    return "CPUs " + ",".join(map(str, ordered))


@contextmanager
def pinned() -> Iterator[str]:
    """Bind this process to fixed CPUs while timing, so that the scheduler does not move it
    between cores mid-measurement; as many CPUs as its libraries use threads (the lowest-numbered
    of those it may run on), restored afterwards. Yields how it ran, for the record ('pinned to
    CPUs 0-1', or 'not pinned (...)' where the OS has no CPU affinity)."""
    try:
        allowed = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        allowed = []
    if not allowed:
        yield "not pinned (this OS sets no CPU affinity)"
        return
    chosen = allowed[: max(1, min(_threads(), len(allowed)))]
    refused = ""
    try:
        os.sched_setaffinity(0, chosen)
    except OSError as exc:
        refused = exc.strerror or str(exc)
    if refused:
        yield f"not pinned ({refused})"
        return
    try:
        yield f"pinned to {_cpu_list(chosen)}"
    finally:
        os.sched_setaffinity(0, allowed)


# --------------------------------------------------------------------------- memory


def _status_kb(field_name: str) -> int | None:
    try:
        with open("/proc/self/status", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith(field_name + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def _reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w", encoding="utf-8") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


@dataclass
class MemoryPeak:
    peak_mb: float | None  # peak RSS during the call minus RSS before it
    peak_rss_mb: float | None  # absolute peak RSS of the process during the call
    method: str


def measure_peak(fn: Callable[[], Any]) -> tuple[Any, MemoryPeak]:
    """Run fn() once and return (its result, the peak extra memory it used)."""
    reset = _reset_peak()
    before = _status_kb("VmRSS")
    result = fn()
    peak = _status_kb("VmHWM")
    if before is None or peak is None:
        return result, MemoryPeak(None, None, "unavailable")
    method = "vmhwm-reset" if reset else "vmhwm-lower-bound"
    return result, MemoryPeak(max(peak - before, 0) / 1024, peak / 1024, method)


# --------------------------------------------------------------------------- timing


@dataclass
class Timing:
    """One timed figure, JSON-ready through `to_dict`."""

    name: str
    median_s: float
    min_s: float
    times_s: list[float]
    median_cpu_s: float  # process CPU time (all threads) per run, less sensitive to contention
    repeats: int
    warmup: int
    n_items: int  # frames (or queries) per timed call
    per_item_ms: float  # median_s / n_items * 1000
    peak_mb: float | None
    peak_rss_mb: float | None
    memory_method: str
    env: Environment
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _check_counts(repeats: int, warmup: int) -> None:
    if repeats < 1 or warmup < 0:
        raise ConfigError(f"need repeats >= 1 and warmup >= 0, got {repeats}, {warmup}")


def time_call(
    fn: Callable[[], Any],
    *,
    name: str = "call",
    repeats: int = 5,
    warmup: int = 1,
    n_items: int = 1,
    memory: bool = True,
) -> Timing:
    """Median wall time of fn() over `repeats` runs after `warmup`; peak memory of one more run."""
    _check_counts(repeats, warmup)
    for _ in range(warmup):
        fn()
    times = []
    cpu = []
    for _ in range(repeats):
        c0 = time.process_time()
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    mem = measure_peak(fn)[1] if memory else MemoryPeak(None, None, "not measured")
    med = statistics.median(times)
    return Timing(name=name, median_s=med, min_s=min(times), times_s=times,
                  median_cpu_s=statistics.median(cpu), repeats=repeats,
                  warmup=warmup, n_items=n_items, per_item_ms=med / max(n_items, 1) * 1e3,
                  peak_mb=mem.peak_mb, peak_rss_mb=mem.peak_rss_mb, memory_method=mem.method,
                  env=environment())


def _check_method(method: Any, maps: Any) -> int:
    if not callable(getattr(method, "describe", None)):
        raise ConfigError(f"{type(method).__name__} has no describe(maps) method")
    try:
        n = len(maps)
    except TypeError:
        raise DataError("maps must be a sequence or an array of frames") from None
    if n == 0:
        raise DataError("no maps to time")
    return n


def time_describe(
    method: Describes,
    maps: Sequence[Any] | np.ndarray,
    *,
    batch_size: int | None = None,
    frames: int | None = 20,
    repeats: int = 5,
    warmup: int = 1,
    name: str | None = None,
) -> Timing:
    """Descriptor time. ``batch_size=None`` or 1: frame by frame (the robot's case, the paper's
    Table III): each timed run describes `frames` frames one at a time, per_item_ms is ms per
    frame. Otherwise all of `maps` (or the first `frames`) in batches of `batch_size`;
    `extra["frames_per_s"]` is the throughput."""
    n_all = _check_method(method, maps)
    n = n_all if frames is None else min(frames, n_all)
    if n < 1:
        raise ConfigError(f"frames must be >= 1, got {frames}")
    bs = 1 if batch_size is None else batch_size
    if bs < 1:
        raise ConfigError(f"batch_size must be >= 1, got {batch_size}")
    subset = maps[:n]

    def run() -> None:
        for lo in range(0, n, bs):
            out = method.describe(subset[lo:lo + bs])
            if getattr(out, "shape", (None,))[0] != len(subset[lo:lo + bs]):
                raise DataError(f"{type(method).__name__}.describe returned "
                                f"{getattr(out, 'shape', type(out))} for "
                                f"{len(subset[lo:lo + bs])} maps")

    label = name or f"{type(method).__name__}.describe[batch={bs}]"
    t = time_call(run, name=label, repeats=repeats, warmup=warmup, n_items=n)
    t.extra.update(batch_size=bs, frames_per_s=n / t.median_s if t.median_s > 0 else None)
    return t


def time_matcher(
    D: np.ndarray,
    *,
    config: Any = None,
    repeats: int = 5,
    warmup: int = 1,
) -> Timing:
    """Matcher time on a difference matrix (per_item_ms is per query)."""
    from safl_bench.matching.matcher import MatcherConfig, match

    cfg = config or MatcherConfig()
    t = time_call(lambda: match(D, cfg), name=f"match[{cfg.method}]", repeats=repeats,
                  warmup=warmup, n_items=int(np.shape(D)[0]))
    t.extra.update(shape=list(np.shape(D)), config=cfg.to_dict())
    return t
