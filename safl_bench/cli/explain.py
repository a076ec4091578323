"""`safl-bench explain`: one cell's difference and enhanced matrices, matches, confidences and
most confident false positives, drawn from its result record to one PNG."""

from __future__ import annotations

import argparse
from pathlib import Path

from safl_bench.cli.options import add_bev_arguments, add_bev_rot_argument, seed

HELP = (
    "Explain one cell (method, task, seed) from its result record: recompute its difference "
    "matrix from the cached views with the record's method and matcher settings and draw one PNG: "
    "the difference and enhanced matrices (the paper's Figure 4), the matched against the true "
    "database frame of every query, each query's confidence (correct or wrong), and the most "
    "confident wrong matches as top views (query, wrong match, true match). A retrieval method "
    "(map_closures) has no difference matrix: its figure says so and draws the rest from the "
    "matches its record holds, without running the method."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--method", required=True, metavar="NAME[@VERSION]",
                        help="the method of the cell (its record's; a bare name is the version `run` runs on the task's data)")
    parser.add_argument("--task", required=True, metavar="ID", help="the task id of the cell")
    parser.add_argument("--seed", type=seed, help="seed of the query noise (default: the task's own)")
    parser.add_argument("--results", metavar="DIR",
                        help="records directory (default: $SAFL_RESULTS or ./results)")
    parser.add_argument("--out", metavar="PNG",
                        help="the figure (default: explain-<method>-<task>-seed<N>.png here; <method> is "
                             "name@VERSION for a version that is not the newest)")
    parser.add_argument("--mode", choices=["sequence", "single_frame"],
                        help="whose matches to explain (default: the sequence matcher's, or "
                             "single_frame for a retrieval method such as map_closures, whose "
                             "records hold only those)")
    parser.add_argument("--top", type=int, default=4, metavar="N",
                        help="how many of the most confident wrong matches to show (default 4)")
    parser.add_argument("--kitti-root", metavar="DIR", help="KITTI odometry root (KITTI tasks)")
    add_bev_arguments(parser)
    add_bev_rot_argument(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def main(args: argparse.Namespace) -> int:
    from safl_bench.analysis.explain import draw, explain, summary
    from safl_bench.errors import ConfigError
    from safl_bench.methods.method import method_selector
    from safl_bench.results.records import default_results_dir
    from safl_bench.run.runner import RunOptions
    from safl_bench.tasks import spec

    if args.top < 0:
        raise ConfigError(f"--top must be >= 0, got {args.top}")
    options = RunOptions(
        results_dir=Path(args.results) if args.results else default_results_dir(),
        seed=args.seed,
        kitti_root=args.kitti_root,
        bev_root=args.bev_root,
        bev_rot_root=args.bev_rot_root,
        bev_resolution_m=args.bev_resolution,
        progress=not args.quiet,
    )
    ex = explain(args.method, args.task, options, top=args.top, mode=args.mode)
    task_id = spec(args.task).id
    method = method_selector(ex.record.method.name, ex.record.method.version)
    shown = "-single_frame" if ex.mode == "single_frame" and not ex.retrieval else ""
    out = Path(args.out) if args.out else Path(
        f"explain-{method}-{task_id.replace('/', '_')}-seed{ex.record.seed}{shown}.png")
    draw(ex, out)
    print(summary(ex))
    print(f"figure: {out}")
    return 0
