"""`safl-bench bench`: print the speed figures the issues set targets for.

  safl-bench bench methods [--method NAME ...]   descriptor ms/frame at batch 1 (Table III),
                                                 batched throughput, 4541² difference matrix
  safl-bench bench matcher [--n 4541] [--dim 1024] [--mode exact|candidates] [--k 10]
                                                 descriptors -> matches, N x N, a planted route
                                                 checked; side by side with the dense path where
                                                 it fits; peak memory, ratio to the plain loop
  safl-bench bench parallel [--workers 2]        map building 1 worker against N, seconds per
                                                 cell serially, on local workers and on Ray
  safl-bench bench images --bev-root DIR         reading a top-view image sequence, cold and
                                                 cached
  safl-bench bench bevplace [--reference DIR]    BEVPlace against its authors' code (run side by
                                                 side) and against the compute bound, both ratios
  safl-bench bench seeds --bev-root DIR          five seeds of a cell against one (stable_afl@1,
                                                 bigan@1 on real 00), interval overhead
  safl-bench bench main-job [--method NAME]       the README's main job from an empty cache and
                                                 cached, wall time and load average
  safl-bench bench retrieval [--method map_closures] [--task ID]   a retrieval method's own
                                                 calls against the harness's whole cell
  safl-bench bench slam [--repeats N]            one loop-closure cell of KITTI 00's size (4541
                                                 poses, 320 closures, three back-ends), median

The map-building and synthetic-LiDAR figures are pytest-benchmark files run from a checkout
(`pytest tests/bench_maps.py tests/bench_synth.py --benchmark-only`), see the README.
"""

from __future__ import annotations

import argparse
import os

from safl_bench.errors import ConfigError

HELP = "print speed figures: descriptor ms/frame per method, matcher time and memory, parallel speed-up"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """`methods` or `matcher`, with their options."""
    from safl_bench.matching.blocks import DEFAULT_BLOCK_MB

    parser.add_argument("what", choices=("methods", "matcher", "parallel", "images", "bevplace", "seeds", "main-job", "retrieval", "slam"), help="what to time")
    parser.add_argument("--method", action="append", help="a method to time, NAME or NAME@VERSION (repeatable; default: every registered "
                        "version; seeds: stable_afl@1, bigan@1)")
    parser.add_argument("--task", default=None, help="task whose clean views are timed (default SAFL/Synth00-T0R0-v6; "
                        "seeds: the cell run, default SAFL/BEVKITTI00-T1R1-v1)")
    parser.add_argument("--frames", type=int, default=None,
                        help="frames per timed batch-1 run (default 50; bevplace: 8)")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs; the median is printed (default 5)")
    parser.add_argument("--n", type=int, default=4541, help="frames of the difference matrix (default 4541, KITTI 00); 0 skips it")
    parser.add_argument("--dim", type=int, default=1024, help="matcher: descriptor length (default 1024)")
    parser.add_argument("--mode", choices=("exact", "candidates"), default="exact",
                        help="matcher: the exact matcher in query blocks, or the candidate search (default exact)")
    parser.add_argument("--k", type=int, default=10, help="matcher: candidates per query in candidate mode (default 10)")
    parser.add_argument("--index", choices=("flat", "ivf"), default="flat",
                        help="matcher: the candidates' FAISS index, exact (flat) or approximate (ivf) (default flat)")
    parser.add_argument("--block-mb", default=None, metavar="MB",
                        help=f"matcher: the exact mode's memory budget per query block (default $SAFL_BLOCK_MB or "
                             f"{DEFAULT_BLOCK_MB})")
    parser.add_argument("--threads", type=int, help="torch CPU threads (default: torch's)")
    parser.add_argument("--sequence", default="00", help="parallel: the sequence whose maps are built (default 00)")
    parser.add_argument("--step", type=int, default=1, help="parallel: frame step (default 1: every frame)")
    parser.add_argument("--workers", type=int, default=2, help="parallel: local workers against one (default 2)")
    parser.add_argument("--ray", default=None, metavar="ADDRESS",
                        help="parallel: 'local' (a Ray cluster started here with --workers CPUs; the "
                             "default where Ray is installed), 'auto', 'ray://HOST:10001' or 'none'")
    parser.add_argument("--kitti-root", metavar="DIR", default=None,
                        help="parallel: KITTI odometry root (default: the synthetic default)")
    parser.add_argument("--bev-root", metavar="DIR", default=None,
                        help="images, seeds: the top-view image folders (BEVPlace's layout); --sequence picks one")
    parser.add_argument("--reference", metavar="DIR", default=None,
                        help="bevplace: the authors' code (a checkout of zjuluolun/BEVPlace, the folder "
                             "holding network/), timed side by side")
    parser.add_argument("--checkpoint", metavar="FILE", default=None,
                        help="bevplace: the authors' checkpoint for their code (default: the shipped weights, the same tensors)")
    parser.add_argument("--batch-size", type=int, default=4, help="bevplace: frames per batch when batched (default 4)")
    parser.add_argument("--plain", action="store_true", help="bevplace: also time the plain port at batch 1")
    parser.add_argument("--json", help="also write every figure, with the environment, to this JSON file")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def main(args: argparse.Namespace) -> int:
    """Run the chosen benchmark and print its table."""
    from safl_bench.common.atomic import atomic_write_json

    if args.frames is None:
        args.frames = 8 if args.what == "bevplace" else 50
    if args.repeats < 1 or args.frames < 1 or args.n < 0:
        raise ConfigError("--repeats and --frames must be >= 1 and --n >= 0")
    if args.threads is not None:
        if args.threads < 1:
            raise ConfigError(f"--threads must be >= 1, got {args.threads}")
        import torch

        torch.set_num_threads(args.threads)
    if args.what == "parallel":
        return _parallel(args)
    if args.what == "images":
        from safl_bench.bench import source_bench

        if args.bev_root is None:
            raise ConfigError("bench images needs --bev-root DIR (top-view image folders)")
        figures = source_bench.run(args.bev_root, args.sequence, repeats=args.repeats)
        print(source_bench.format_results(figures))
        if args.json:
            atomic_write_json(args.json, figures)
        return 0
    if args.what == "bevplace":
        return _bevplace(args)
    if args.what == "seeds":
        return _seeds(args)
    if args.what == "slam":
        from safl_bench.bench import slam_bench

        print(slam_bench.format_results(slam_bench.run(args.repeats or 3)))
        return 0
    if args.what == "retrieval":
        from safl_bench.bench import retrieval_bench

        figures = retrieval_bench.run(
            args.method[0] if args.method else retrieval_bench.DEFAULT_METHOD,
            args.task or retrieval_bench.DEFAULT_TASK, kitti_root=args.kitti_root,
            bev_root=args.bev_root or os.environ.get("SAFL_BEV_ROOT"), repeats=args.repeats)
        print(retrieval_bench.format_results(figures))
        if args.json:
            atomic_write_json(args.json, figures)
        return 0
    if args.what == "main-job":
        from safl_bench.bench import main_job_bench

        figures = main_job_bench.run(args.method[0] if args.method else "stable_afl")
        print(main_job_bench.format_results(figures))
        if args.json:
            atomic_write_json(args.json, figures)
        return 0 if figures.get("cached_s_returncode") == 0 else 1
    if args.what == "matcher":
        from safl_bench.bench import matching_bench

        argv = ["--n", str(args.n or 4541), "--repeats", str(args.repeats),
                "--dim", str(args.dim), "--mode", args.mode, "--k", str(args.k),
                "--index", args.index]
        if args.block_mb is not None:
            argv += ["--block-mb", str(args.block_mb)]
        if args.json:
            argv += ["--json", args.json]
        return matching_bench.main(argv)

    from safl_bench.bench import method_bench

    results = method_bench.run(
        args.method, task_id=args.task or method_bench.DEFAULT_TASK, frames=args.frames,
        repeats=args.repeats, matrix_n=args.n or None, progress=not args.quiet,
    )
    print(method_bench.format_results(results))
    if args.json:
        atomic_write_json(args.json, results)
    return 0


def _parallel(args: argparse.Namespace) -> int:
    from safl_bench.bench import parallel_bench
    from safl_bench.common.atomic import atomic_write_json
    from safl_bench.sources import resolve_source

    if args.step < 1:
        raise ConfigError(f"--step must be >= 1, got {args.step}")
    source = resolve_source(args.kitti_root, sequences=[args.sequence], progress=not args.quiet)
    source.sequence(args.sequence)  # a missing sequence is named here, before any timing
    results = parallel_bench.run(
        source.root, args.sequence, step=args.step, workers=args.workers,
        ray_address=args.ray or parallel_bench.default_ray(), progress=not args.quiet,
    )
    print(parallel_bench.format_results(results))
    if args.json:
        atomic_write_json(args.json, results)
    return 0


def _bevplace(args: argparse.Namespace) -> int:
    from baselines import bevplace_bench
    from safl_bench.common.atomic import atomic_write_json

    if args.batch_size < 1:
        raise ConfigError(f"--batch-size must be >= 1, got {args.batch_size}")
    views, note = bevplace_bench.load_views(args.bev_root, args.sequence, args.frames)
    result = bevplace_bench.run(views, reference=args.reference, checkpoint=args.checkpoint,
                                batch_size=args.batch_size, rounds=args.repeats, plain=args.plain)
    result["views"] = note
    print(bevplace_bench.format_results(result, note))
    if args.json:
        atomic_write_json(args.json, result)
    return 0


def _seeds(args: argparse.Namespace) -> int:
    from safl_bench.bench import seeds_bench
    from safl_bench.common.atomic import atomic_write_json

    bev_root = args.bev_root or os.environ.get("SAFL_BEV_ROOT")
    if bev_root is None:
        raise ConfigError("bench seeds needs --bev-root DIR (top-view image folders in "
                          "BEVPlace's layout, e.g. BEVPlace/data/KITTI) or $SAFL_BEV_ROOT")
    result = seeds_bench.run(bev_root, args.method, task_id=args.task or seeds_bench.DEFAULT_TASK,
                             repeats=args.repeats)
    print(seeds_bench.format_results(result))
    if args.json:
        atomic_write_json(args.json, result)
    return 0
