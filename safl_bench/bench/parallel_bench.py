"""Benchmark of the scale-out (issue 8): map building with 1 worker against N, and the time per
benchmark cell serially, on N local workers and on a Ray cluster (the Ray path's overhead).

    safl-bench bench parallel [--sequence 00] [--step 1] [--workers 2] [--ray local|auto|none]

Maps are built into a scratch cache (a temporary $SAFL_HOME, deleted afterwards), so both map
builds start from no maps (and both from scans in the page cache); the scans come from the synthetic default (generated first if missing) or
`--kitti-root`. The cells are SAD on the sequence's twelve paper conditions, with the maps the
builds cached: what is measured is the fan-out, not the rendering.
"""

from __future__ import annotations

import os
import tempfile
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from safl_bench.common.parallel import Parallel
from safl_bench.errors import ConfigError
from safl_bench.run import timing


def _ray_available() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def default_ray() -> str:
    """'local' where Ray is installed, else 'none'."""
    return "local" if _ray_available() else "none"


def run(
    root: Path,
    sequence: str = "00",
    *,
    step: int = 1,
    workers: int = 2,
    ray_address: str = "none",
    progress: bool = False,
) -> dict[str, Any]:
    """Every figure, JSON-ready. `root`: a KITTI-layout root holding `sequence`."""
    from safl_bench.methods.method import make_method
    from safl_bench.run import runner
    from safl_bench.sources import kitti_source
    from safl_bench.tasks import register, registry, unregister
    from safl_bench.views import mapcache
    from safl_bench.views.mapbuild import select_frames
    from safl_bench.views.mapconfig import MapConfig
    from safl_bench.views.noise import CLEAN, PAPER_CONDITIONS

    if workers < 2:
        raise ConfigError(f"--workers must be >= 2 to compare with one worker, got {workers}")
    if ray_address != "none" and not _ray_available():
        raise ConfigError("--ray needs Ray: pip install 'safl-bench[ray]' (or --ray none)")
    source = kitti_source(root)
    frames = select_frames(len(source.sequence(sequence)), step)
    conditions = [CLEAN, *PAPER_CONDITIONS]
    out: dict[str, Any] = {"sequence": sequence, "step": step, "frames": len(frames),
                           "conditions": len(conditions), "workers": workers}
    home_before = os.environ.get("SAFL_HOME")
    with tempfile.TemporaryDirectory(prefix="safl-bench-parallel-") as scratch:
        os.environ["SAFL_HOME"] = scratch  # workers inherit it
        ids = [f"Bench/Par{sequence}-{c.name}-v0" for c in PAPER_CONDITIONS]
        try:
            for scan in sorted((Path(root) / "sequences" / sequence / "velodyne").glob("*.bin")):
                scan.read_bytes()  # into the page cache, so the first build is not the only cold one
            seconds = {}
            for n in (1, workers):
                for f in mapcache.map_cache_dir().rglob("*.npz"):
                    f.unlink()
                t0 = time.perf_counter()
                mapcache.prepare(source, sequence, MapConfig(), frames=frames, conditions=conditions,
                                 seed=0, progress=progress, parallel=Parallel(workers=n))
                seconds[n] = time.perf_counter() - t0
            out["map_building"] = {"one_worker_s": seconds[1], "workers_s": seconds[workers],
                                   "speedup": seconds[1] / seconds[workers]}

            for task_id, c in zip(ids, PAPER_CONDITIONS, strict=True):
                register(task_id, source="kitti", sequence=sequence, condition=c, step=step,
                         n_seeds=1)  # one cell per task: the bench times cells, not seeds
            sad = make_method("sad")
            runs = [("serial", Parallel()), ("local", Parallel(workers=workers))]
            if ray_address != "none":
                import ray

                env = {"SAFL_HOME": scratch}
                if ray_address == "local":
                    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False,
                             runtime_env={"env_vars": env})
                else:
                    Parallel(ray_address=ray_address).slots()  # joins, or a clear error
                runs.append(("ray", Parallel(ray_address="auto" if ray_address == "local" else ray_address)))
            per_cell = {}
            try:
                for label, parallel in runs:
                    options = runner.RunOptions(results_dir=Path(scratch) / "results" / label,
                                                kitti_root=str(root), progress=progress,
                                                timing_frames=5, timing_repeats=2)
                    t0 = time.perf_counter()
                    outcomes = runner.run_cells(sad, ids, options, parallel=parallel, log=lambda m: None)
                    failed = [o.message for o in outcomes if o.status != "computed"]
                    if failed:
                        raise ConfigError(f"a benchmark cell failed ({label}): {failed[0]}")
                    per_cell[label] = (time.perf_counter() - t0) / len(ids)
            finally:
                if ray_address != "none":
                    import ray

                    ray.shutdown()
            out["cells"] = {"n": len(ids), **{f"{k}_s_per_cell": v for k, v in per_cell.items()}}
            if "ray" in per_cell:
                out["cells"]["ray_overhead_s_per_cell"] = per_cell["ray"] - per_cell["local"]
                out["cells"]["ray_address"] = ray_address
        finally:
            for task_id in ids:
                if task_id in registry:
                    unregister(task_id)
            if home_before is None:
                os.environ.pop("SAFL_HOME", None)
            else:
                os.environ["SAFL_HOME"] = home_before
    out["environment"] = asdict(timing.environment())
    return out


def format_results(r: dict[str, Any]) -> str:
    """The figures as a few lines of text."""
    m, c, w = r["map_building"], r["cells"], r["workers"]
    lines = [
        f"map building, sequence {r['sequence']} (frame step {r['step']}), {r['frames']} frames x "
        f"{r['conditions']} conditions: 1 worker {m['one_worker_s']:.1f} s, {w} workers "
        f"{m['workers_s']:.1f} s -> speed-up {m['speedup']:.2f}x",
        f"SAD, {c['n']} cells with cached maps, seconds per cell: serial {c['serial_s_per_cell']:.2f}, "
        f"{w} local workers {c['local_s_per_cell']:.2f}"
        + (f", Ray ({c['ray_address']}) {c['ray_s_per_cell']:.2f}" if "ray_s_per_cell" in c else ""),
    ]
    if "ray_overhead_s_per_cell" in c:
        lines.append(f"Ray overhead per cell against local workers: {c['ray_overhead_s_per_cell']:+.2f} s")
    return "\n".join(lines)
