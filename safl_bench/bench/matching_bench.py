"""Benchmark of the shared matcher: descriptors -> difference matrix -> SeqSLAM matches.

``python -m safl_bench.bench.matching_bench`` (or `main()`, for a CLI to wire up) prints the median
time and peak memory on a KITTI-00-sized problem (4541 x 4541 frames, 1024-d float32 random
descriptors), the split between distance and matching, and the speed ratio against the plain-loop
reference (`safl_bench.matching.loop`) on a smaller matrix. Target (issue 4): <= 1.5 s, < 2 GB.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from safl_bench.matching import loop as matching_loop
from safl_bench.matching import matcher as matching
from safl_bench.methods import distance
from safl_bench.run import timing


def run(n: int = 4541, dim: int = 1024, *, repeats: int = 5, loop_n: int = 100,
        seed: int = 0) -> dict[str, Any]:
    """All the figures as a JSON-ready dict."""
    rng = np.random.default_rng(seed)
    q = rng.standard_normal((n, dim), dtype=np.float32)
    db = rng.standard_normal((n, dim), dtype=np.float32)
    cfg = matching.MatcherConfig()
    matching.seqslam(np.ones((12, 12)))  # compile / load the numba kernels outside the clock

    def end_to_end() -> matching.MatchResult:
        return matching.match(distance.sqeuclidean(q, db), cfg)

    total = timing.time_call(end_to_end, name="descriptors->matches", repeats=repeats,
                             n_items=n)
    D = distance.sqeuclidean(q, db)
    dist = timing.time_call(lambda: distance.sqeuclidean(q, db), name="distance",
                            repeats=repeats, n_items=n, memory=False)
    search = timing.time_matcher(D, config=cfg, repeats=repeats)
    del D

    small = rng.random((loop_n, loop_n))
    cfg64 = matching.MatcherConfig(dtype="float64")
    fast = timing.time_call(lambda: matching.match(small, cfg64), name="vectorised-small",
                            repeats=repeats, n_items=loop_n, memory=False)
    t0 = time.perf_counter()
    matching_loop.ref_match(small, cfg64)
    loop_s = time.perf_counter() - t0
    return {
        "problem": {"n_queries": n, "n_database": n, "dim": dim, "dtype": "float32"},
        "end_to_end": total.to_dict(),
        "distance": dist.to_dict(),
        "matcher": search.to_dict(),
        "loop_ratio": {"n": loop_n, "loop_s": loop_s, "vectorised_s": fast.median_s,
                       "ratio": loop_s / fast.median_s},
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="safl_bench.bench.matching_bench", description=__doc__)
    ap.add_argument("--n", type=int, default=4541, help="frames in queries and database")
    ap.add_argument("--dim", type=int, default=1024, help="descriptor length")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--loop-n", type=int, default=100, help="matrix size for the loop ratio")
    ap.add_argument("--json", help="also write all figures to this JSON file")
    args = ap.parse_args(argv)
    res = run(args.n, args.dim, repeats=args.repeats, loop_n=args.loop_n)
    e2e, dist, srch, lr = res["end_to_end"], res["distance"], res["matcher"], res["loop_ratio"]
    env = e2e["env"]
    print(f"problem: {args.n} x {args.n}, {args.dim}-d float32 descriptors; "
          f"{env['cpu_model']}, {env['usable_cpus']} CPUs, numba threads {env['numba_threads']}")
    print(f"descriptors -> matches: median {e2e['median_s']:.3f} s (min {e2e['min_s']:.3f}, "
          f"{e2e['repeats']} runs; CPU {e2e['median_cpu_s']:.3f} s), "
          f"peak +{e2e['peak_mb']:.0f} MB ({e2e['memory_method']}); load avg {env['load_avg_1m']}")
    print(f"  distance matrix     : median {dist['median_s']:.3f} s "
          f"(CPU {dist['median_cpu_s']:.3f} s)")
    print(f"  enhancement+search  : median {srch['median_s']:.3f} s "
          f"(CPU {srch['median_cpu_s']:.3f} s), "
          f"peak +{srch['peak_mb']:.0f} MB")
    print(f"plain loop on {lr['n']} x {lr['n']}: {lr['loop_s']:.2f} s vs vectorised "
          f"{lr['vectorised_s'] * 1e3:.2f} ms -> {lr['ratio']:.0f}x")
    if args.json:
        from safl_bench.common.atomic import atomic_write_json

        atomic_write_json(args.json, res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
