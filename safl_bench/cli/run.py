"""`safl-bench run`: run a method on benchmark tasks, store one record per cell, print a table."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from safl_bench.cli.options import (
    add_bev_arguments,
    add_bev_rot_argument,
    add_parallel_arguments,
    parallel_from,
    parse_key_values,
    seed,
    seed_count,
    source_kind,
)

HELP = (
    "Run methods on benchmark tasks (default: the paper's twelve conditions on the embedded "
    "synthetic default's test sequence), generating and caching whatever data is missing. One "
    "JSON record per (method, task, seed) cell is written; existing records are reused unless "
    "--force."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from safl_bench.matching.blocks import DEFAULT_BLOCK_MB
    from safl_bench.tasks.builtin import SUITES

    parser.add_argument("--method", required=True, action="append",
                        help="registered method (safl-bench list methods); repeatable: the grid "
                             "method x task x seed runs as one queue")
    parser.add_argument(
        "--task", action="append", default=[], metavar="ID|SUITE",
        help=f"task id or suite ({', '.join(SUITES)}); repeatable; default: paper",
    )
    parser.add_argument("--kitti-root", metavar="DIR", help="KITTI odometry root: run the KITTI tasks")
    add_bev_arguments(parser)
    add_bev_rot_argument(parser)
    seeds = parser.add_mutually_exclusive_group()
    seeds.add_argument("--seeds", type=seed_count, metavar="N",
                       help="run the first N noise seeds of each task whose queries are random "
                            "(default: all the seeds the task declares, five; a task where nothing "
                            "is random has one, run 3 times, as seeds 0-2, by a method that "
                            "cannot be seeded, such as map_closures)")
    seeds.add_argument("--seed", type=seed, action="append", metavar="S",
                       help="run exactly this noise seed on every task; repeatable")
    parser.add_argument("--results", metavar="DIR", help="records directory (default: $SAFL_RESULTS or ./results)")
    parser.add_argument("--force", action="store_true", help="recompute cells whose record exists")
    parser.add_argument("--slam", action="store_true",
                        help="after the cells, run each revisit cell through the loop-closure stage "
                             "at its deployed threshold (safl-bench slam --deployed; needs "
                             "safl-bench[slam])")
    parser.add_argument(
        "--weights", metavar="PATH|shipped|untrained",
        help="learned methods: a weights file from `safl-bench train`, the shipped ones for each "
        "task's data (default; a bare name runs the newest version that ships them), or "
        "'untrained': score the random networks (records and tables mark them '(untrained)')",
    )
    parser.add_argument(
        "--param", action="append", default=[], metavar="KEY=VALUE",
        help="method parameter (VALUE parsed as JSON when it can be, else a string); repeatable",
    )
    parser.add_argument(
        "--score", choices=("min", "ratio"), default="min",
        help="matcher score: the paper's lowest S (min) or OpenSeqSLAM's ratio (default: min)",
    )
    parser.add_argument(
        "--matcher", action="append", default=[], metavar="KEY=VALUE",
        help="sequence-matcher setting (safl_bench.matching.matcher.MatcherConfig), e.g. enhance_window=0 "
        "or ds=5; repeatable; recorded with every result (default: the paper's Table I)",
    )
    parser.add_argument(
        "--matcher-preset", default="paper", metavar="NAME",
        help="named matcher settings, refined by --score and --matcher: paper (default: Table I, "
        "Eq. 5-7), authors (the authors' public code), openseqslam; safl-bench list matchers",
    )
    parser.add_argument(
        "--block-mb", metavar="MB", default=None,
        help="memory budget of the difference matrix's query blocks: the matcher holds about this "
        f"much of it at a time, whatever the frames (default: $SAFL_BLOCK_MB or {DEFAULT_BLOCK_MB}); "
        "changes no result (safl_bench.matching.blocks)")
    # --score refines the preset only when given (the paper preset's score is "min", as before)
    parser.set_defaults(score=None)
    add_parallel_arguments(parser, "build the views and evaluate the cells",
                           ray_note="; a grid of fewer cells than a cluster of more CPUs than "
                                    "this machine has each cell's describing and matching "
                                    "spread over it")
    parser.add_argument("--quiet", action="store_true",
                        help="no progress: no bars on a terminal, no line per finished cell in a "
                        "log (where stderr is not a terminal)")


def matcher_config(score: str | None, items: list[str], preset: str = "paper") -> Any:
    """The evaluation's matcher settings (an `EvaluationConfig`): the preset (default: the
    paper's), then `--score` when given, then the `--matcher` pairs; an unknown preset or
    setting is a ConfigError naming the valid ones."""
    from safl_bench.matching import presets as matcher_presets

    changes = parse_key_values(items, "--matcher")
    if score is not None:
        changes = {"score": score, **changes}
    return matcher_presets.configure(preset, changes, flag="--matcher")


def distinct_seeds(seeds: list[int]) -> list[int]:
    """`--seed` values in order; one given twice is a ConfigError naming it (it would run one
    cell twice and weigh it twice in a mean)."""
    from safl_bench.errors import ConfigError

    repeated = sorted({s for s in seeds if seeds.count(s) > 1})
    if repeated:
        raise ConfigError(f"--seed {', '.join(map(str, repeated))} given more than once; give "
                          "each seed once")
    return seeds


def weights_line(method: Any, source: str) -> str | None:
    """One line saying which version of a configured method runs on `source` and with which
    weights (its record says the same: ``method.version``, ``method.params.weights``); None for
    a method without weights (it learns nothing: the run's last line names its version)."""
    from safl_bench.methods.method import SOURCE_WORDS

    info = method.weights_info
    if not info:
        return None
    where = SOURCE_WORDS.get(source, (source, ""))[0]
    kind = info.get("source")
    if kind == "untrained":
        what = (f"its UNTRAINED (random) networks, seed {info.get('seed')}, as --weights untrained "
                "asks; records and tables mark them (untrained)")
    elif kind == "shipped":
        what = f"its shipped weights {info.get('path')}"
    elif kind == "file":
        what = f"the weights file {info.get('path')}"
    else:
        what = f"the weights {info.get('path')} ({kind})"
    return f"{method.name}@{method.version} on {where}: {what}"


def main(args: argparse.Namespace) -> int:
    from safl_bench.errors import ConfigError
    from safl_bench.methods.method import make_method, method_class
    from safl_bench.results.records import default_results_dir
    from safl_bench.run.runner import RunOptions, resolve_tasks, run_grid, summary_table
    from safl_bench.tasks import spec

    if args.block_mb is not None:  # checked before any work; the workers read it from the env
        from safl_bench.matching import blocks

        os.environ[blocks.BLOCK_MB_ENV] = repr(blocks.block_mb(args.block_mb, "--block-mb"))
    names = list(dict.fromkeys(args.method))
    if len(names) > 1 and (args.weights or args.param):
        raise ConfigError("--weights and --param apply to one method: give them with a single --method")
    for name in names:
        method_class(name)  # an unknown name fails before any work
    task_ids = resolve_tasks(args.task, source=source_kind(args))
    params = parse_key_values(args.param, "--param")
    # trainable methods take the weights trained on each task's kind of data (shipped ones differ
    # between the synthetic default and real top views), so the grid runs per source
    by_source: dict[str, list[str]] = {}
    for task_id in task_ids:
        by_source.setdefault(spec(task_id).source, []).append(task_id)
    seeds = distinct_seeds(args.seed) if args.seed else None
    evaluation = matcher_config(args.score, args.matcher, args.matcher_preset)
    from safl_bench.sources import missing_data

    # options are checked first (a typo is named whatever the data), then the data folders,
    # before any work rather than per cell after start-up
    missing = [m for m in (missing_data(spec(t), kitti_root=args.kitti_root, bev_root=args.bev_root,
                                        bev_rot_root=args.bev_rot_root) for t in task_ids) if m]
    if missing:
        more = f" (and {len(missing) - 1} more tasks)" if len(missing) > 1 else ""
        raise ConfigError(missing[0] + more)
    options = RunOptions(
        results_dir=Path(args.results) if args.results else default_results_dir(),
        force=args.force,
        kitti_root=args.kitti_root,
        bev_root=args.bev_root,
        bev_rot_root=args.bev_rot_root,
        bev_resolution_m=args.bev_resolution,
        evaluation=evaluation,
        progress=not args.quiet,
    )
    parallel = parallel_from(args)
    # a bare name runs, per source, the newest version with weights for it (`resolve_method`);
    # a version without them fails here, before any work
    built = {source: [make_method(name, weights=args.weights, source=source, **params)
                      for name in names] for source in by_source}
    if options.evaluation.candidates is not None:  # before any work: a method it cannot search
        from safl_bench.evaluation.cell import check_candidates
        from safl_bench.matching.candidates import faiss_module

        if options.evaluation.index == "ivf":  # the flat index is the project's own search
            faiss_module()
        for methods in built.values():
            for method in methods:
                check_candidates(method, options.evaluation)
    outcomes = []
    ran: list[str] = []
    for source, ids in by_source.items():
        for method in built[source]:  # which version and weights, once, before the progress bars
            line = weights_line(method, source)
            if line is not None:
                print(line, flush=True)
        ran += [f"{m.name}@{m.version}" for m in built[source]]
        outcomes += run_grid(built[source], ids, options, seeds=seeds, n_seeds=args.seeds,
                             parallel=parallel)
    labels = ', '.join(dict.fromkeys(ran))
    print(f"{labels} — records in {options.results_dir}")
    print(summary_table(outcomes))
    if args.slam:
        from safl_bench.cli.slam import after_cells

        after_cells(outcomes, options.results_dir, kitti_root=args.kitti_root,
                    bev_root=args.bev_root, bev_resolution_m=args.bev_resolution)
    failed = [o for o in outcomes if o.status == "failed"]
    if failed:
        print(f"safl-bench: {len(failed)} of {len(outcomes)} cells failed (see above); "
              "rerun to retry them", file=sys.stderr)
        return 2
    return 0
