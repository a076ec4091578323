"""`safl-bench slam`: what one cell's loop closures do to the trajectory, from its result record."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from safl_bench.run.runner import CellOutcome

from safl_bench.cli.options import add_bev_arguments, seed, seed_count

HELP = (
    "Run one cell (method, revisit task, seed) through a pose-graph back-end from its result "
    "record (no descriptor is recomputed): the task's ground-truth motion with seeded odometry "
    "drift, the record's matches above a confidence threshold as loop closures (true ones with "
    "registration noise, false ones random), solved by GTSAM with least squares, a Cauchy kernel "
    "and GNC (truncated least squares); prints ATE and RPE (evo) of each beside the odometry "
    "alone and writes them as JSON beside the record. Needs safl-bench[slam] (gtsam, evo). "
    "Modelling choices and sources: docs/reference/slam-stage.md."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from safl_bench.slam.model import DEFAULT_DRIFT, DRIFT_LEVELS

    parser.add_argument("--method", required=True, metavar="NAME[@VERSION]",
                        help="the method of the cell (its record's; a bare name is the version run "
                             "on the task's data)")
    parser.add_argument("--task", required=True, metavar="ID", help="a revisit task's id")
    parser.add_argument("--seed", type=seed, help="the cell's seed (default: the task's own); "
                                                  "it also seeds the drift and closure noise")
    parser.add_argument("--threshold", type=float, metavar="CONFIDENCE",
                        help="accept matches with at least this confidence (within the record's "
                             "range); default: the oracle operating point, the lowest threshold "
                             "whose closures are all true, chosen on this cell; confidences are "
                             "negative scores: write --threshold=-12.5")
    parser.add_argument("--threshold-from", metavar="ID",
                        help="deploy the threshold chosen on another task instead: the lowest that "
                             "keeps 100 %% precision in the method's record there (same seed), "
                             "e.g. KITTI 02's revisit task for KITTI 00's")
    parser.add_argument("--deployed", action="store_true",
                        help="deploy the threshold of the task's fixed partner sequence "
                             "(safl_bench.slam.cell.DEPLOY_FROM: KITTI 00<->02, 05<->06, Synth00<->09), "
                             "the leaderboard's operating point")
    parser.add_argument("--slam-seeds", type=seed_count, metavar="N",
                        help="run SLAM seeds 0 to N-1 from the one record: seed s draws the "
                             "odometry drift and closure noise s, the same for every method "
                             "(default 5; 1 with --out); prints the mean and 95 %% interval over them")
    parser.add_argument("--curve", type=int, metavar="N",
                        help="instead of one threshold, N from no closure to every match (evenly "
                             "spaced quantiles of the confidences): one line each, the curve as JSON "
                             "(default slam-curve-seed-<n>.json beside the record)")
    parser.add_argument("--plot", metavar="PNG",
                        help="also draw the cell: ground truth, odometry and each back-end's "
                             "trajectory with true/false closures (SLAM seed 0); with --curve, "
                             "ATE against closures accepted of this method and those of --also")
    parser.add_argument("--also", action="append", default=[], metavar="NAME[@VERSION]",
                        help="with --curve: another method's curve on the same axes (repeatable)")
    parser.add_argument("--drift", choices=list(DRIFT_LEVELS), default=DEFAULT_DRIFT,
                        help="odometry drift level (default %(default)s; docs/reference/slam-stage.md)")
    parser.add_argument("--mode", choices=["sequence", "single_frame"],
                        help="whose matches become closures (default: the sequence matcher's, or "
                             "single_frame for a method whose records hold only those, a retrieval "
                             "method such as map_closures)")
    parser.add_argument("--rpe-delta", type=float, default=100.0, metavar="M",
                        help="the distance of the RPE in metres (default %(default)s)")
    parser.add_argument("--results", metavar="DIR",
                        help="records directory (default: $SAFL_RESULTS or ./results)")
    parser.add_argument("--out", metavar="JSON",
                        help="the result file (default: slam-seed-<n>.json beside the record)")
    parser.add_argument("--kitti-root", metavar="DIR", help="KITTI odometry root (KITTI tasks)")
    add_bev_arguments(parser)


def main(args: argparse.Namespace) -> int:
    import dataclasses
    import json

    from safl_bench.common.atomic import atomic_write_text
    from safl_bench.errors import ConfigError, DataError
    from safl_bench.methods.method import method_class, resolve_method
    from safl_bench.results.records import (
        ResultRecord,
        default_results_dir,
        load_record,
        record_path,
    )
    from safl_bench.slam.cell import (
        DEFAULT_SLAM_SEEDS,
        SlamSettings,
        curve_table,
        deploy_source,
        deployed_threshold,
        result_path,
        run_seeds,
        settings_key,
        summary_table,
        table,
        threshold_curve,
        write_result,
    )
    from safl_bench.tasks.registry import runnable_spec
    from safl_bench.tasks.task import Task

    results = Path(args.results) if args.results else default_results_dir()
    registered = runnable_spec(args.task)
    cell_seed = registered.seed if args.seed is None else int(args.seed)
    cls = method_class(resolve_method(args.method, registered.source))
    if "@" not in args.method and cls.trainable:  # which version a bare name means, as run says
        print(f"{cls.name}@{cls.version}: what a bare {args.method!r} runs on this task's data "
              f"(the newest version with weights for it)", flush=True)

    def make_it(task_id: str) -> str:
        """The run command that makes the cell's record, with this command's own data and
        results options, so that it writes where this command reads."""
        from safl_bench.analysis.explain import run_command

        flags = {"--kitti-root": args.kitti_root, "--bev-root": getattr(args, "bev_root", None)}
        return run_command(f"{cls.name}@{cls.version}", task_id, seed=cell_seed,
                           results=args.results, source_options=flags)

    def _existing(path: Path) -> Path:
        if not path.is_file():
            raise DataError(f"no record {path}; make it with: {make_it(registered.id)}")
        return path

    def record_of(task_id: str) -> ResultRecord:
        path = record_path(results, cls.name, cls.version, task_id, cell_seed)
        if not path.is_file():
            from safl_bench.methods.method import method_versions

            held = [v for v in method_versions(cls.name) if v != cls.version and record_path(
                results, cls.name, v, task_id, cell_seed).is_file()]
            other = (f"; {', '.join(f'{cls.name}@{v}' for v in held)} has one: pass "
                     f"--method {cls.name}@{held[-1]}") if held else ""
            raise DataError(f"no record of {cls.name}@{cls.version} on {task_id} seed {cell_seed} in "
                            f"{results}{other}; or make it with: {make_it(task_id)}")
        return load_record(path)

    record = record_of(registered.id)
    if args.mode is None:
        args.mode = "sequence" if "sequence" in record.results else "single_frame"
    threshold, rule = args.threshold, None
    if args.curve is not None and (args.threshold is not None or args.threshold_from is not None):
        raise ConfigError("--curve takes its own thresholds: give it without --threshold and "
                          "--threshold-from")
    if args.deployed:
        if args.threshold_from is not None or args.threshold is not None:
            raise ConfigError("--deployed chooses the threshold itself: give it without "
                              "--threshold and --threshold-from")
        args.threshold_from = deploy_source(registered.id)
    if args.threshold_from is not None:
        if args.threshold is not None:
            raise ConfigError("give --threshold or --threshold-from, not both")
        other = runnable_spec(args.threshold_from).id
        threshold = deployed_threshold(record_of(other), args.mode)
        rule = (f"deployed: the lowest keeping 100 % precision on {other} seed {cell_seed}, chosen "
                "there" + ("" if threshold is not None else "; none does, so no closure"))
    spec = registered if cell_seed == registered.seed else dataclasses.replace(registered, seed=cell_seed)
    task = Task.from_spec(spec, kitti_root=args.kitti_root, bev_root=args.bev_root,
                          bev_resolution_m=args.bev_resolution, progress=False)
    try:
        import evo  # noqa: F401
        import gtsam  # noqa: F401
    except ImportError:
        raise DataError("the loop-closure stage needs gtsam and evo: pip install "
                        "'safl-bench[slam]'") from None
    settings = SlamSettings(mode=args.mode, drift=args.drift, threshold=threshold,
                            rpe_delta_m=args.rpe_delta, threshold_rule=rule)
    if args.curve is not None:
        curve = threshold_curve(record, task, settings, args.curve)
        default = result_path(results, record)
        out = Path(args.out) if args.out else default.with_name(default.name.replace("slam-", "slam-curve-"))
        atomic_write_text(out, json.dumps({"curve": [r.to_json() for r in curve]}, indent=2,
                                          sort_keys=True, allow_nan=False) + "\n")
        print(curve_table(curve))
        print(f"result: {out}")
        if args.plot:
            from safl_bench.leaderboard.slam_figures import curve_figure

            curves = {curve[0].method: curve}
            for name in args.also:
                other_cls = method_class(resolve_method(name, registered.source))
                other_record = load_record(_existing(record_path(
                    results, other_cls.name, other_cls.version, registered.id, cell_seed)))
                curves[f"{other_cls.name}@{other_cls.version}"] = threshold_curve(
                    other_record, task, settings, args.curve)
                print(curve_table(curves[f"{other_cls.name}@{other_cls.version}"]))
            curve_figure(curves, Path(args.plot))
            print(f"picture: {args.plot}")
        return 0
    if args.also:
        raise ConfigError("--also adds curves: give it with --curve and --plot")
    if args.out and args.slam_seeds in (None, 1):
        seeded = dataclasses.replace(settings, seed=0)
        result = run_seeds(record, task, seeded, [0])[0]
        print(table(result))
        print(f"result: {write_result(Path(args.out), result)}")
        return 0
    if args.out:
        raise ConfigError("--out names one result file: give it with --slam-seeds 1")
    runs = run_seeds(record, task, settings, range(args.slam_seeds or DEFAULT_SLAM_SEEDS), results)
    if len(runs) == 1:
        print(table(runs[0]))
    else:
        print(summary_table(runs))
    print(f"results: {result_path(results, record, dataclasses.replace(settings, seed=0)).parent}"
          f" (slam-*.s<seed>.{settings_key(settings)}.json)")
    if args.plot:
        from safl_bench.leaderboard.slam_figures import trajectory_figure
        from safl_bench.slam.cell import cell_trajectories

        trajectory_figure(cell_trajectories(record, task, dataclasses.replace(settings, seed=0)),
                          Path(args.plot))
        print(f"picture: {args.plot}")
    return 0


def after_cells(outcomes: list[CellOutcome], results_dir: Path, *, kitti_root: str | None = None,
                bev_root: str | None = None, bev_resolution_m: float | None = None) -> None:
    """`safl-bench run --slam`: each revisit cell just run (not failed) through the loop-closure
    stage at its deployed threshold (`slam.cell.DEPLOY_FROM`, the partner sequence's record of the
    same method and seed, from this run or `results_dir`), over the default SLAM seeds, result
    files beside the records (a re-run resumes); a cell whose partner has no record, or whose
    task has no partner, is named with the command that runs it instead."""
    import dataclasses

    from safl_bench.errors import SaflError
    from safl_bench.results.records import is_repeat, load_record, record_path
    from safl_bench.slam.cell import (
        DEFAULT_SLAM_SEEDS,
        DEPLOY_FROM,
        SlamSettings,
        deployed_threshold,
        run_seeds,
        summary_table,
    )
    from safl_bench.tasks.registry import runnable_spec
    from safl_bench.tasks.task import Task

    for o in outcomes:
        record = o.record
        if o.status == "failed" or record is None or record.task.protocol != "revisit":
            continue
        if is_repeat(record):  # a repeated run of an unseedable method: the first run is scored
            continue
        cell = f"{record.method.name}@{record.method.version} on {record.task.id} seed {record.seed}"
        partner = DEPLOY_FROM.get(record.task.id)
        other = None if partner is None else record_path(
            results_dir, record.method.name, record.method.version, partner, record.seed)
        if other is None or not other.is_file():
            print(f"slam: {cell}: no " + (f"record on its partner {partner} to deploy a threshold from; "
                  "run that task too" if partner else "deployment partner for its task")
                  + f", or: safl-bench slam --method {record.method.name}@{record.method.version} "
                  f"--task {record.task.id} --threshold-from ID")
            continue
        try:
            mode = "sequence" if "sequence" in record.results else "single_frame"
            threshold = deployed_threshold(load_record(other), mode)
            settings = SlamSettings(mode=mode, threshold=threshold, threshold_rule=(
                f"deployed: the lowest keeping 100 % precision on {partner} seed {record.seed}, "
                "chosen there" + ("" if threshold is not None else "; none does, so no closure")))
            spec = runnable_spec(record.task.id)
            if spec.seed != record.seed:
                spec = dataclasses.replace(spec, seed=record.seed)
            task = Task.from_spec(spec, kitti_root=kitti_root, bev_root=bev_root,
                                  bev_resolution_m=bev_resolution_m, progress=False)
            print(summary_table(run_seeds(record, task, settings, range(DEFAULT_SLAM_SEEDS),
                                          results_dir)))
        except (SaflError, ImportError) as error:
            print(f"slam: {cell}: {error}")
