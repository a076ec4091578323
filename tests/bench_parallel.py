"""Benchmark: speed-up of the grid with 2 workers against 1, and the per-cell overhead of the
Ray path against local workers (issue 8). Uses the embedded default's sequence 09 (generated on
first use) with a throw-away map cache.

    python tests/bench_parallel.py [SEQUENCE [STEP]]   # default 09 and every 4th frame

Not a timed test: the default test run skips benchmarks (it has no test functions).
"""

from __future__ import annotations

import os
import tempfile
import time


def main() -> int:
    import sys

    from safl_bench import synth

    name = sys.argv[1] if len(sys.argv) > 1 else "09"
    step = int(sys.argv[2]) if len(sys.argv) > 2 else 4
    root = synth.default_root()
    synth.ensure(root, [name], progress=False)  # before SAFL_HOME moves to the scratch cache
    with tempfile.TemporaryDirectory() as scratch:
        os.environ["SAFL_HOME"] = scratch
        from safl_bench import mapcache, runner
        from safl_bench.datasource import kitti_source
        from safl_bench.mapbuild import select_frames
        from safl_bench.mapconfig import MapConfig
        from safl_bench.method_registry import make_method
        from safl_bench.noise import CLEAN, PAPER_CONDITIONS
        from safl_bench.parallel import Parallel
        from safl_bench.tasks import register, unregister

        source = kitti_source(root)
        frames = select_frames(len(source.sequence(name)), step)
        conds = [CLEAN, *PAPER_CONDITIONS]
        seconds = {}
        for workers in (1, 2):
            for f in (mapcache.map_cache_dir()).rglob("*.npz"):
                f.unlink()
            t0 = time.perf_counter()
            mapcache.prepare(source, name, MapConfig(), frames=frames, conditions=conds, seed=0,
                             progress=False, parallel=Parallel(workers=workers))
            seconds[workers] = time.perf_counter() - t0
        print(f"map building, sequence {name}, {len(frames)} frames x {len(conds)} conditions: "
              f"1 worker {seconds[1]:.1f} s, 2 workers {seconds[2]:.1f} s -> speed-up {seconds[1] / seconds[2]:.2f}x")

        os.environ["SAFL_KITTI_ROOT"] = str(root)
        ids = [f"Bench/Par{name}-{c.name}-v0" for c in PAPER_CONDITIONS]
        for task_id, c in zip(ids, PAPER_CONDITIONS, strict=True):
            register(task_id, source="kitti", sequence=name, condition=c, step=step)  # maps cached above
        sad = make_method("sad")
        per_cell = {}
        import ray

        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
                 runtime_env={"env_vars": {"SAFL_HOME": scratch, "SAFL_KITTI_ROOT": str(root)}})
        for label, parallel in (("serial", Parallel()), ("2 local workers", Parallel(workers=2)),
                                ("Ray, 2 CPUs", Parallel(ray_address="auto"))):
            opts = runner.RunOptions(results_dir=os.path.join(scratch, label.replace(" ", "_")), progress=False,
                                     timing_frames=5, timing_repeats=2)  # type: ignore[arg-type]
            t0 = time.perf_counter()
            out = runner.run_cells(sad, ids, opts, parallel=parallel)
            assert all(o.status == "computed" for o in out), [o.message for o in out]
            per_cell[label] = (time.perf_counter() - t0) / len(ids)
        ray.shutdown()
        for task_id in ids:
            unregister(task_id)
        print(f"sad, {len(ids)} cells (maps cached), seconds per cell: "
              + ", ".join(f"{k} {v:.2f}" for k, v in per_cell.items())
              + f"; Ray overhead per cell against local workers {per_cell['Ray, 2 CPUs'] - per_cell['2 local workers']:+.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
