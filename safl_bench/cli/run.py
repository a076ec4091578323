"""`safl-bench run`: run a method on benchmark tasks, store one record per cell, print a table."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from safl_bench.cli.options import (
    add_bev_arguments,
    add_parallel_arguments,
    parallel_from,
    parse_key_values,
    seed,
    source_kind,
)

HELP = (
    "Run methods on benchmark tasks (default: the paper's twelve conditions on the embedded "
    "synthetic default's test sequence), generating and caching whatever data is missing. One "
    "JSON record per (method, task, seed) cell is written; existing records are reused unless "
    "--force."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--method", required=True, action="append",
                        help="registered method (safl-bench list methods); repeatable: the grid "
                             "method x task x seed runs as one queue")
    parser.add_argument(
        "--task", action="append", default=[], metavar="ID|SUITE",
        help="task id or suite (paper, paper-full, revisit, sanity, all); repeatable; default: paper",
    )
    parser.add_argument("--kitti-root", metavar="DIR", help="KITTI odometry root: run the KITTI tasks")
    add_bev_arguments(parser)
    parser.add_argument("--seed", type=seed, action="append",
                        help="seed of the query noise (default: the task's own); repeatable")
    parser.add_argument("--results", metavar="DIR", help="records directory (default: $SAFL_RESULTS or ./results)")
    parser.add_argument("--force", action="store_true", help="recompute cells whose record exists")
    parser.add_argument(
        "--weights", metavar="PATH|shipped|untrained",
        help="learned methods: a weights file from `safl-bench train`, the shipped ones (default) "
        "or the untrained networks",
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
        help="sequence-matcher setting (safl_bench.matching.MatcherConfig), e.g. enhance_window=0 "
        "or ds=5; repeatable; recorded with every result (default: the paper's Table I)",
    )
    add_parallel_arguments(parser, "build the views and evaluate the cells")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def matcher_config(score: str, items: list[str]) -> Any:
    """The sequence matcher's settings: the paper's defaults, `--score`, then `--matcher` pairs."""
    import dataclasses

    from safl_bench.errors import ConfigError
    from safl_bench.matching import MatcherConfig

    settings = {"score": score, **parse_key_values(items, "--matcher")}
    valid = {f.name for f in dataclasses.fields(MatcherConfig)} - {"method"}
    unknown = sorted(set(settings) - valid)
    if unknown:
        raise ConfigError(f"--matcher: unknown setting(s) {unknown}; valid: {sorted(valid)}")
    return MatcherConfig(**settings)


def main(args: argparse.Namespace) -> int:
    from safl_bench.errors import ConfigError
    from safl_bench.evaluation import EvaluationConfig
    from safl_bench.method_registry import make_method
    from safl_bench.records import default_results_dir
    from safl_bench.runner import RunOptions, resolve_tasks, run_grid, summary_table

    names = list(dict.fromkeys(args.method))
    if len(names) > 1 and (args.weights or args.param):
        raise ConfigError("--weights and --param apply to one method: give them with a single --method")
    task_ids = resolve_tasks(args.task, source=source_kind(args))
    methods = [make_method(name, weights=args.weights, **parse_key_values(args.param, "--param"))
               for name in names]
    seeds = list(dict.fromkeys(args.seed)) if args.seed else [None]
    options = RunOptions(
        results_dir=Path(args.results) if args.results else default_results_dir(),
        seed=seeds[0],
        force=args.force,
        kitti_root=args.kitti_root,
        bev_root=args.bev_root,
        bev_resolution_m=args.bev_resolution,
        evaluation=EvaluationConfig(matcher_config(args.score, args.matcher)),
        progress=not args.quiet,
    )
    outcomes = run_grid(methods, task_ids, options, seeds=seeds, parallel=parallel_from(args))
    print(f"{', '.join(f'{m.name}@{m.version}' for m in methods)} — records in {options.results_dir}")
    print(summary_table(outcomes))
    failed = [o for o in outcomes if o.status == "failed"]
    if failed:
        print(f"safl-bench: {len(failed)} of {len(outcomes)} cells failed (see above); "
              "rerun to retry them", file=sys.stderr)
        return 2
    return 0
