"""Benchmark of the shared matcher: descriptors -> matches, at any size, in either mode.

``safl-bench bench matcher --n N --dim D --mode exact|candidates [--k K] [--json FILE]`` times
N queries against N database frames (seeded random descriptors with a planted route, so that
correctness is checked too) in the chosen mode:

* ``exact``: the matcher in query blocks (`safl_bench.matching.blocks`), its difference rows
  computed block by block from the descriptors, as a cell computes them;
* ``candidates``: the candidate search (`safl_bench.matching.candidates`) through each query's
  K nearest frames: with the ``flat`` index, one pass over the difference rows, block by block
  (`candidates.search_rows`); with ``ivf``, FAISS's index and its search, then the sequence
  search.

Where the whole difference matrix fits in memory (`dense_fits`), the dense path (the whole
matrix, then `matcher.match`) is timed in the same run, side by side, and the chosen mode's
matches are compared with it: ``identical_to_dense`` is whether index, score and velocity are
the same numbers (exact mode) or whether the matched frames are (candidate mode, whose scores
come from other arithmetic), and null where the dense path does not fit; ``agree_with_dense``
is the share of queries matched to the same frame. The dense sections
of the KITTI-00-sized problem (``end_to_end``, ``distance``, ``matcher``, ``loop_ratio``: the
split between distance and matching, and the speed ratio against the plain-loop reference)
come along where it fits.

The planted route: the database is N random unit-variance descriptors; queries 0 .. N/2 - 1
drive database frames N/4 .. 3N/4 - 1 again in order (each the frame plus noise of a quarter
of its spread), the rest are new places. ``route_found`` is the share of planted queries
(those with a full trajectory) whose sequence match is their own frame +- 1.

Peak memory is the process's RSS high-water mark during the first run (which also gives the
matches that are checked), minus the RSS before it (`safl_bench.run.timing.measure_peak`); the
timed runs follow it (``seconds`` is their median, ``first_run_s`` the first run's time).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from safl_bench.errors import ConfigError
from safl_bench.matching import blocks, candidates
from safl_bench.matching import loop as matching_loop
from safl_bench.matching import matcher as matching
from safl_bench.methods import distance
from safl_bench.run import timing

MODES = ("exact", "candidates")
#: The dense path is run where its two (N, N) float32 matrices fit in this share of the
#: memory available now.
DENSE_SHARE = 0.5


def dense_fits(n: int) -> bool:
    """Whether the dense path's two N x N float32 matrices (D and its enhancement) fit in
    `DENSE_SHARE` of the memory available now (MemAvailable; 8 GB where it cannot be read)."""
    available = 8e9
    try:
        with open("/proc/meminfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    available = float(line.split()[1]) * 1024
    except OSError:
        pass
    return 2 * 4 * float(n) * n <= DENSE_SHARE * available


def planted(n: int, dim: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(queries, database, planted frame per query, -1 for a new place): module doc."""
    rng = np.random.default_rng(seed)
    db = rng.standard_normal((n, dim), dtype=np.float32)
    q = rng.standard_normal((n, dim), dtype=np.float32)
    half = n // 2
    truth = np.full(n, -1, np.int64)
    truth[:half] = n // 4 + np.arange(half)
    q[:half] = db[truth[:half]] + 0.25 * rng.standard_normal((half, dim), dtype=np.float32)
    return q, db, truth


def route_found(result: matching.MatchResult, truth: np.ndarray) -> float:
    """Share of planted queries with a full trajectory matched to their frame +- 1."""
    mask = (truth >= 0) & result.complete
    if not mask.any():
        return float("nan")
    return float(np.mean(np.abs(result.index[mask] - truth[mask]) <= 1))


def run(n: int = 4541, dim: int = 1024, *, mode: str = "exact", k: int = 10,
        index: str = "flat", repeats: int = 5, loop_n: int = 100, seed: int = 0,
        block_mb: float | None = None) -> dict[str, Any]:
    """All the figures as a JSON-ready dict (module doc)."""
    if mode not in MODES:
        raise ConfigError(f"--mode must be one of {', '.join(MODES)}, got {mode!r}")
    if not isinstance(n, int) or n < 8:
        raise ConfigError(f"--n must be a whole number of frames >= 8, got {n!r}")
    if not isinstance(dim, int) or dim < 1:
        raise ConfigError(f"--dim must be a whole number >= 1, got {dim!r}")
    if mode == "candidates":
        candidates.check_k(k, n)
        if index == "ivf":
            candidates.faiss_module()
    budget = blocks.block_mb(block_mb, "--block-mb")
    q, db, truth = planted(n, dim, seed)
    cfg = matching.MatcherConfig()
    matching.seqslam(np.ones((12, 12)))  # compile / load the numba kernels outside the clock
    step = blocks.block_rows(n, n, budget, copies=3 if mode == "exact" else 2)

    def exact() -> matching.MatchResult:
        (res,), _ = blocks.match_rows(lambda a, b: distance.sqeuclidean(q[a:b], db), n, n,
                                      [cfg], block=step)
        return res

    def through_candidates() -> matching.MatchResult:
        if index == "flat":
            _, (res,), _ = candidates.search_rows(
                lambda a, b: distance.sqeuclidean(q[a:b], db), n, n, k, [cfg], block=step)
            return res
        cand = candidates.nearest(q, db, k, index=index)
        return candidates.match_candidates(q, db, cand, cfg)

    if mode == "candidates":  # compile the kernels outside the clock
        small_q, small_db, _ = planted(16, 4)
        candidates.match_candidates(small_q, small_db, candidates.nearest(small_q, small_db, 2),
                                    cfg)
        candidates.search_rows(lambda a, b: distance.sqeuclidean(small_q[a:b], small_db), 16,
                               16, 2, [cfg])
    fn = exact if mode == "exact" else through_candidates
    t0 = time.perf_counter()
    result, peak = timing.measure_peak(fn)  # the first run: its matches and its memory
    first_s = time.perf_counter() - t0
    timed = timing.time_call(fn, name=f"descriptors->matches[{mode}]", repeats=repeats,
                             warmup=0, n_items=n, memory=False)
    out: dict[str, Any] = {
        "frames": n, "dim": dim, "mode": mode, "seconds": timed.median_s,
        "peak_mb": peak.peak_mb, "peak_rss_mb": peak.peak_rss_mb, "memory_method": peak.method,
        "route_found": route_found(result, truth),
        "identical_to_dense": None, "agree_with_dense": None,
        "k": k if mode == "candidates" else None,
        "index": index if mode == "candidates" else None,
        "block_rows": step if mode == "exact" or index == "flat" else None, "block_mb": budget,
        "first_run_s": first_s, "timing": timed.to_dict(),
        "problem": {"n_queries": n, "n_database": n, "dim": dim, "dtype": "float32",
                    "planted_queries": int((truth >= 0).sum()), "seed": seed},
        "dense": None, "end_to_end": None, "distance": None, "matcher": None,
        "loop_ratio": None,
    }
    if dense_fits(n):
        out.update(_dense(q, db, cfg, repeats, loop_n, seed))
        dense_result = matching.match(distance.sqeuclidean(q, db), cfg)
        out["dense"] = {"seconds": out["end_to_end"]["median_s"],
                        "peak_mb": out["end_to_end"]["peak_mb"],
                        "route_found": route_found(dense_result, truth)}
        out["identical_to_dense"] = _same(result, dense_result, exact=mode == "exact")
        out["agree_with_dense"] = float(np.mean(result.index == dense_result.index))
        out["speed_ratio_to_dense"] = out["end_to_end"]["median_s"] / timed.median_s
    return out


def _same(a: matching.MatchResult, b: matching.MatchResult, *, exact: bool) -> bool:
    if not np.array_equal(a.index, b.index):
        return False
    if not exact:
        return True
    return bool(np.array_equal(a.score, b.score) and np.array_equal(a.velocity, b.velocity,
                                                                     equal_nan=True))


def _dense(q: np.ndarray, db: np.ndarray, cfg: matching.MatcherConfig, repeats: int,
           loop_n: int, seed: int) -> dict[str, Any]:
    """The dense path's sections: end to end, its split, and the plain-loop ratio."""
    n = len(q)

    def end_to_end() -> matching.MatchResult:
        return matching.match(distance.sqeuclidean(q, db), cfg)

    total = timing.time_call(end_to_end, name="descriptors->matches[dense]", repeats=repeats,
                             n_items=n)
    D = distance.sqeuclidean(q, db)
    dist = timing.time_call(lambda: distance.sqeuclidean(q, db), name="distance",
                            repeats=repeats, n_items=n, memory=False)
    search = timing.time_matcher(D, config=cfg, repeats=repeats)
    del D
    rng = np.random.default_rng(seed)
    small = rng.random((loop_n, loop_n))
    cfg64 = matching.MatcherConfig(dtype="float64")
    fast = timing.time_call(lambda: matching.match(small, cfg64), name="vectorised-small",
                            repeats=repeats, n_items=loop_n, memory=False)
    t0 = time.perf_counter()
    matching_loop.ref_match(small, cfg64)
    loop_s = time.perf_counter() - t0
    return {"end_to_end": total.to_dict(), "distance": dist.to_dict(), "matcher": search.to_dict(),
            "loop_ratio": {"n": loop_n, "loop_s": loop_s, "vectorised_s": fast.median_s,
                           "ratio": loop_s / fast.median_s}}


def format_results(res: dict[str, Any]) -> str:
    """The figures as the command prints them."""
    env = res["timing"]["env"]
    blocks_of = f", blocks of {res['block_rows']} rows" if res["block_rows"] else ""
    mode = res["mode"] + (f", k={res['k']}, {res['index']} index" if res["mode"] == "candidates"
                          else "") + blocks_of
    lines = [f"problem: {res['frames']} x {res['frames']}, {res['dim']}-d float32 descriptors, "
             f"half of the queries on a planted route; {env['cpu_model']}, "
             f"{env['usable_cpus']} CPUs, numba threads {env['numba_threads']}, "
             f"load avg {env['load_avg_1m']}",
             f"{res['mode']} ({mode}): median {res['seconds']:.3f} s over "
             f"{res['timing']['repeats']} runs (first {res['first_run_s']:.3f} s), peak "
             f"+{res['peak_mb']:.0f} MB (process {res['peak_rss_mb']:.0f} MB); planted route "
             f"found {100 * res['route_found']:.1f} %"]
    if res["dense"] is None:
        lines.append("dense path: not run (its two N x N matrices do not fit in half of the "
                     "memory available); identical_to_dense: null")
        return "\n".join(lines)
    e2e, dist, srch, lr = res["end_to_end"], res["distance"], res["matcher"], res["loop_ratio"]
    same = "identical" if res["identical_to_dense"] else "NOT identical"
    what = "matches, scores and velocities" if res["mode"] == "exact" else "matched frames"
    lines += [
        f"dense path (whole matrix): median {e2e['median_s']:.3f} s (CPU "
        f"{e2e['median_cpu_s']:.3f} s), peak +{e2e['peak_mb']:.0f} MB; {what} {same} to it "
        f"({100 * res['agree_with_dense']:.1f} % of queries matched the same frame); "
        f"{res['mode']} / dense time {1 / res['speed_ratio_to_dense']:.2f}",
        f"  distance matrix     : median {dist['median_s']:.3f} s (CPU {dist['median_cpu_s']:.3f} s)",
        f"  enhancement+search  : median {srch['median_s']:.3f} s (CPU {srch['median_cpu_s']:.3f} s), "
        f"peak +{srch['peak_mb']:.0f} MB",
        f"plain loop on {lr['n']} x {lr['n']}: {lr['loop_s']:.2f} s vs vectorised "
        f"{lr['vectorised_s'] * 1e3:.2f} ms -> {lr['ratio']:.0f}x"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="safl_bench.bench.matching_bench", description=__doc__)
    ap.add_argument("--n", type=int, default=4541, help="frames in queries and database")
    ap.add_argument("--dim", type=int, default=1024, help="descriptor length")
    ap.add_argument("--mode", choices=MODES, default="exact")
    ap.add_argument("--k", type=int, default=10, help="candidates per query (candidate mode)")
    ap.add_argument("--index", choices=candidates.INDEXES, default="flat")
    ap.add_argument("--block-mb", default=None, help="the exact mode's block budget (MB)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--loop-n", type=int, default=100, help="matrix size for the loop ratio")
    ap.add_argument("--json", help="also write all figures to this JSON file")
    args = ap.parse_args(argv)
    res = run(args.n, args.dim, mode=args.mode, k=args.k, index=args.index,
              repeats=args.repeats, loop_n=args.loop_n, block_mb=args.block_mb)
    print(format_results(res))
    if args.json:
        from safl_bench.common.atomic import atomic_write_json

        atomic_write_json(args.json, res)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
