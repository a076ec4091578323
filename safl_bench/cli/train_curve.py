"""`safl-bench train-curve`: a training run's snapshots on test tasks, AUC against steps.

The paper's Figure 14 (AUC against training progress) from the encoders `safl-bench train
--snapshot-every K` saved; see `safl_bench.analysis.training_curve` for every choice (the
authors' four conditions on sequence 00, which is the TEST sequence; one noise seed; the
`authors` matcher preset). Writes into --out (default <run>/curve): records/step<N>/ (one record
per snapshot, task and seed; reused when run again), train_log.jsonl (the figure's data, read by
`safl-bench leaderboard` when the folder sits under its training-logs/) and, with
--select-best, best-on-test.safetensors (the snapshot the authors' way of choosing would take,
its weights saying it was selected on the test set).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from safl_bench.cli.options import add_bev_arguments, seed, source_kind
from safl_bench.errors import ConfigError

HELP = "evaluate a training run's snapshots: AUC against training steps (the paper's Figure 14)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", type=Path, help="the --out folder of `safl-bench train --snapshot-every K`")
    parser.add_argument("--task", action="append", metavar="ID",
                        help="task id; repeatable (default: sequence 00 at T1R2, T5R2, T10R2, T20R2 "
                             "on the run's kind of data)")
    parser.add_argument("--kitti-root", help="KITTI odometry root (for KITTI tasks)")
    add_bev_arguments(parser)
    parser.add_argument("--matcher-preset", default="authors", metavar="NAME",
                        help="matcher preset (default: authors); safl-bench list matchers")
    parser.add_argument("--seed", type=seed, default=0, help="noise seed of the tasks (default 0)")
    parser.add_argument("--select-best", action="store_true",
                        help="also write best-on-test.safetensors: the snapshot with the highest mean AUC, "
                             "marked as selected on the test set")
    parser.add_argument("--out", type=Path, help="output folder (default: RUN/curve)")


def main(args: argparse.Namespace) -> int:
    from safl_bench.analysis.training_curve import CURVE_CONDITIONS, measure_curve, snapshots
    from safl_bench.matching import presets
    from safl_bench.tasks.builtin import paper_id
    from safl_bench.views.noise import Condition

    if not args.run.is_dir():
        raise ConfigError(f"{args.run} is not a training run's folder")
    snapshots(args.run)  # none: one line, before any task is opened
    kind = source_kind(args)
    tasks = args.task or [paper_id(kind, "00", Condition.parse(c)) for c in CURVE_CONDITIONS]
    evaluation = presets.configure(args.matcher_preset, {})
    out = args.out or args.run / "curve"
    measure_curve(args.run, tasks, out, evaluation=evaluation, bev_root=args.bev_root,
                  kitti_root=args.kitti_root, seed=args.seed, select_best=args.select_best,
                  log=lambda m: print(m, file=sys.stderr))
    print(f"wrote {out / 'train_log.jsonl'}")
    return 0
