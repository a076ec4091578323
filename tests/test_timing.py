"""The timing harness returns sane, JSON-ready structures (no speed is asserted)."""

from __future__ import annotations

import dataclasses
import json
import os

import numpy as np
import pytest

from safl_bench import timing
from safl_bench.errors import ConfigError, DataError
from safl_bench.matching import MatcherConfig


class Flatten:
    """A minimal method: describe(maps) -> (N, D)."""

    def __init__(self) -> None:
        self.calls: list[int] = []

    def describe(self, maps: np.ndarray) -> np.ndarray:
        self.calls.append(len(maps))
        return np.asarray(maps, dtype=np.float32).reshape(len(maps), -1)


class Broken:
    def describe(self, maps: np.ndarray) -> np.ndarray:
        return np.zeros((len(maps) + 1, 3))


def test_environment_records_hardware_threads_versions() -> None:
    env = timing.environment()
    assert env.logical_cpus >= 1 and env.usable_cpus >= 1 and env.cpu_model
    assert "numpy" in env.versions and "numba" in env.versions
    assert env.numba_threads is None or env.numba_threads >= 1
    assert json.loads(json.dumps(dataclasses.asdict(env)))["cpu_model"] == env.cpu_model


def test_time_describe_batch1_and_batched() -> None:
    maps = np.random.default_rng(0).random((12, 8, 8), dtype=np.float32)
    m = Flatten()
    t = timing.time_describe(m, maps, frames=6, repeats=3, warmup=1)
    assert t.n_items == 6 and t.repeats == 3 and len(t.times_s) == 3
    assert m.calls == [1] * 6 * 5  # warm-up, 3 timed, 1 for memory
    assert t.median_s > 0 and t.per_item_ms == pytest.approx(t.median_s / 6 * 1e3)
    assert t.extra["batch_size"] == 1 and t.extra["frames_per_s"] > 0
    m2 = Flatten()
    tb = timing.time_describe(m2, maps, batch_size=5, frames=None, repeats=2, warmup=0)
    assert tb.n_items == 12 and m2.calls == [5, 5, 2] * 3
    blob = json.loads(json.dumps(tb.to_dict()))
    assert blob["env"]["versions"]["numpy"] and blob["memory_method"]


def test_time_describe_errors() -> None:
    maps = np.zeros((4, 2, 2))
    with pytest.raises(DataError):
        timing.time_describe(Broken(), maps, repeats=1, warmup=0)
    with pytest.raises(ConfigError):
        timing.time_describe(object(), maps)  # type: ignore[arg-type]
    with pytest.raises(DataError):
        timing.time_describe(Flatten(), maps[:0])
    with pytest.raises(ConfigError):
        timing.time_describe(Flatten(), maps, repeats=0)
    with pytest.raises(ConfigError):
        timing.time_describe(Flatten(), maps, batch_size=0)


def test_time_matcher_and_memory() -> None:
    D = np.random.default_rng(0).random((30, 40))
    t = timing.time_matcher(D, config=MatcherConfig(), repeats=2, warmup=1)
    assert t.n_items == 30 and t.extra["shape"] == [30, 40]
    assert t.extra["config"]["ds"] == 10
    if t.memory_method.startswith("vmhwm"):
        assert t.peak_mb is not None and t.peak_mb >= 0


def test_measure_peak_sees_a_large_allocation() -> None:
    def alloc() -> float:
        # 64 MB of fresh anonymous pages, touched: memory the allocator cannot hand back from
        # pages an earlier test left resident (in the full suite np.ones could reuse them)
        import mmap

        block = mmap.mmap(-1, 64 * 1024 * 1024)
        a = np.frombuffer(block, dtype=np.float64)
        a[:] = 1.0
        total = float(a.sum())
        del a
        block.close()
        return total

    value, mem = timing.measure_peak(alloc)
    assert value == 64 * 1024 * 1024 // 8
    if mem.method == "vmhwm-reset":
        assert mem.peak_mb is not None and mem.peak_mb > 50


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="this OS sets no CPU affinity")
def test_pinned_binds_to_fixed_cpus_and_restores_them() -> None:
    before = os.sched_getaffinity(0)
    with timing.pinned() as how:
        inside = os.sched_getaffinity(0)
        assert how.startswith("pinned to CPU")
        assert inside <= before and 1 <= len(inside) <= max(timing._threads(), 1)
        assert min(inside) == min(before)
    assert os.sched_getaffinity(0) == before
    with pytest.raises(RuntimeError), timing.pinned():
        raise RuntimeError("the timed call failed")
    assert os.sched_getaffinity(0) == before  # restored on errors too
