"""`safl-bench data resampling`: resampled queries (as an image source makes them, with empty
corners) against re-rendered ones, on tasks whose queries can be re-rendered.

For every method, task and noise seed it evaluates three sets of queries on the same database,
frames and noise draws (`safl_bench.analysis.resampling`: re-rendered, resampled, masked) and
writes to --out, atomically: ``resampling.md`` (tables), ``resampling.csv`` (every number) and
``config.json`` (what was run, with the command). The evaluations are kept under
``--out``/cells, so a rerun with more tasks or seeds computes only what is missing.
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from safl_bench.cli.options import seed, seed_count

HELP = ("compare resampled queries (an image source's, with empty corners) with re-rendered ones "
        "on the same frames, noise draws and database: per method and condition, each "
        "measure and the paired difference with its 95 % interval")
DEFAULT_METHODS = ("sad", "stable_afl@1", "bigan@1")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags of `data resampling`."""
    from safl_bench.analysis.resampling import DEFAULT_MEASURES
    from safl_bench.evaluation.uncertainty import measure_names
    from safl_bench.matching.settings import MODES

    parser.add_argument("--out", required=True, metavar="DIR",
                        help="folder of the report (resampling.md, resampling.csv, config.json) "
                             "and of the evaluations it reuses (cells/)")
    parser.add_argument("--method", action="append", metavar="NAME[@VERSION]",
                        help=f"repeatable; default: {' '.join(DEFAULT_METHODS)} (a bare name is "
                             "the newest version)")
    parser.add_argument("--task", action="append", metavar="ID|SUITE",
                        help="paper-protocol task ids or suites with viewpoint noise, on a "
                             "source with scans; repeatable; default: paper (the synthetic "
                             "default's twelve conditions on 00)")
    seeds = parser.add_mutually_exclusive_group()
    seeds.add_argument("--seeds", type=seed_count, metavar="N",
                       help="the first N noise seeds of each task (default: all it declares)")
    seeds.add_argument("--seed", type=seed, action="append", metavar="S",
                       help="exactly this noise seed on every task; repeatable")
    parser.add_argument("--matcher-preset", default="authors", metavar="NAME",
                        help="matcher settings (safl-bench list matchers; default %(default)s)")
    parser.add_argument("--matcher", action="append", default=[], metavar="KEY=VALUE",
                        help="a matcher setting on top of the preset; repeatable")
    parser.add_argument("--mode", choices=MODES, default="sequence",
                        help="matching mode reported (default %(default)s)")
    parser.add_argument("--measure", action="append", choices=measure_names(),
                        help=f"repeatable; default: {' '.join(DEFAULT_MEASURES)}")
    parser.add_argument("--kitti-root", metavar="DIR", help="KITTI odometry root (KITTI tasks)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def command_line(methods: list[str], tasks: list[str], seeds: tuple[int, ...], args: argparse.Namespace) -> str:
    """The canonical command that makes this report (every choice spelled out)."""
    words = ["safl-bench", "data", "resampling", "--out", str(args.out)]
    for name in methods:
        words += ["--method", name]
    for task_id in tasks:
        words += ["--task", task_id]
    for s in seeds:
        words += ["--seed", str(s)]
    words += ["--matcher-preset", args.matcher_preset]
    for item in args.matcher:
        words += ["--matcher", item]
    words += ["--mode", args.mode]
    for measure in args.measure or []:
        words += ["--measure", measure]
    if args.kitti_root:
        words += ["--kitti-root", args.kitti_root]
    return shlex.join(words)


def main(args: argparse.Namespace) -> int:
    from safl_bench import __version__
    from safl_bench.analysis import resampling
    from safl_bench.cli.run import distinct_seeds, matcher_config
    from safl_bench.common.atomic import atomic_write_json, atomic_write_text
    from safl_bench.common.fingerprint import to_jsonable
    from safl_bench.errors import ConfigError
    from safl_bench.evaluation.uncertainty import BLOCK, REPLICATES
    from safl_bench.matching import presets
    from safl_bench.methods.method import Method, make_method, method_class
    from safl_bench.results.provenance import git_revision
    from safl_bench.run.runner import cell_seeds, method_info, resolve_tasks
    from safl_bench.tasks import spec

    names = list(dict.fromkeys(args.method or DEFAULT_METHODS))
    for name in names:
        method_class(name)  # an unknown name fails before any work
    evaluation = matcher_config(None, args.matcher, args.matcher_preset)
    task_ids = resolve_tasks(args.task or ["paper"], source="kitti" if args.kitti_root else "synth")
    for task_id in task_ids:
        s = spec(task_id)
        if s.source == "bev":
            raise ConfigError(f"task {task_id}: its queries are resampled top-view images already; "
                              "give tasks on the synthetic default or KITTI scans")
        if s.protocol != "paper" or s.condition.is_clean:
            raise ConfigError(f"task {task_id}: needs the paper protocol with viewpoint noise "
                              f"(protocol {s.protocol}, condition {s.condition})")
    chosen = [cell_seeds(spec(t), distinct_seeds(args.seed) if args.seed else None, args.seeds)
              for t in task_ids]
    if any(c != chosen[0] for c in chosen):
        raise ConfigError("the tasks declare different seeds; give them with --seed")
    seeds = chosen[0]
    out = resampling.check_out(Path(args.out))
    made: dict[str, list[Method]] = {}

    def methods(source: str) -> list[Method]:
        if source not in made:
            made[source] = [make_method(n, source=source) for n in names]
        return made[source]

    experiment = resampling.Experiment(tuple(task_ids), tuple(seeds), evaluation, args.mode,
                                       args.kitti_root)
    results = resampling.run(experiment, methods, out / "cells", progress=not args.quiet,
                             log=print)
    measures = list(dict.fromkeys(args.measure or resampling.DEFAULT_MEASURES))
    config = {
        "command": command_line(names, task_ids, seeds, args),
        "safl_bench_version": __version__,
        "git_revision": git_revision(),
        "methods": {f"{m.name}@{m.version}": to_jsonable(method_info(m).params)
                    for ms in made.values() for m in ms},
        "tasks": task_ids,
        "seeds": list(seeds),
        "matcher": presets.settings(evaluation),
        "mode": args.mode,
        "measures": measures,
        "arms": list(resampling.ARMS),
        "differences": [f"{a} - {b}" for a, b in resampling.DIFFERENCES],
        "bootstrap": {"replicates": REPLICATES, "block": BLOCK},
        "cell_version": resampling.CELL_VERSION,
    }
    atomic_write_text(out / "resampling.csv", resampling.csv_text(results, measures))
    atomic_write_text(out / "resampling.md", resampling.markdown_text(results, measures, config))
    atomic_write_json(out / "config.json", to_jsonable(config))
    print(f"report: {out / 'resampling.md'} (and resampling.csv, config.json)")
    return 0
