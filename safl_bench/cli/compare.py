"""`safl-bench compare`: two methods on the same tasks, paired over the same seeds and queries.

For each task it reads both methods' records (every seed both have), prints each measure's mean
over those seeds with its 95 % interval for A, for B and for A - B (`safl_bench.evaluation.uncertainty`:
a two-level block bootstrap over seeds and queries, the same resamples for both methods), and a
one-line verdict: which measures A wins or loses beyond the noise, and which are tied.
"""

from __future__ import annotations

import argparse
import functools
import sys
from collections import defaultdict
from pathlib import Path

from safl_bench.errors import ConfigError, DataError
from safl_bench.evaluation.metrics import Outcomes
from safl_bench.evaluation.uncertainty import measure_names, sample
from safl_bench.results.records import MODES, ResultRecord, default_results_dir, load_records

HELP = ("compare two methods task by task: means with 95 % intervals over seeds and queries, "
        "the paired difference and a verdict")
DEFAULT_MEASURES = ("recall_at_100_precision", "f1_max", "recall_at_1", "auc")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--method", action="append", required=True, metavar="NAME[@VERSION]",
                   help="give exactly two: A, then B (a bare name is the version `run` runs on "
                        "the records' data; name@VERSION picks one, e.g. two versions of one "
                        "method)")
    p.add_argument("--task", action="append", metavar="ID|SUITE",
                   help="task id or suite (as for `run`); repeatable; default: every task both "
                        "methods have records of")
    p.add_argument("--source", choices=("synth", "kitti", "bev"), default="synth",
                   help="which tasks a suite name means (default: synth)")
    p.add_argument("--results", type=Path, default=None,
                   help="records directory (default: $SAFL_RESULTS or ./results)")
    p.add_argument("--mode", choices=MODES, default="sequence", help="matching mode")
    p.add_argument("--measure", action="append", choices=measure_names(),
                   help=f"repeatable; default: {', '.join(DEFAULT_MEASURES)}")


def _pick(records: list[ResultRecord], text: str) -> dict[str, dict[int, ResultRecord]]:
    """{task id: {seed: record}} of one method at one version: `name@V`, or for a bare name the
    version `safl-bench run --method name` runs on each record's data source (`resolve_method`:
    for a learned method the newest version with weights for it; the newest version with
    records when the name is not registered here). Records of two versions never mix in a cell."""
    from safl_bench.methods.method import method_versions, resolve_method, version_key

    name, _, version = text.partition("@")
    mine = [r for r in records if r.method.name == name]
    if not mine:
        raise DataError(f"no records of method {name!r} (methods with records: "
                        f"{', '.join(sorted({r.method.name for r in records})) or 'none'})")
    held = sorted({r.method.version for r in mine}, key=version_key)
    registered = method_versions(name)

    @functools.cache
    def wanted(source: str) -> str:
        if version:
            return version
        return resolve_method(name, source).partition("@")[2] if registered else held[-1]

    out: dict[str, dict[int, ResultRecord]] = defaultdict(dict)
    for r in mine:
        if r.method.version == wanted(r.task.source_kind):
            out[r.task.id][r.seed] = r
    if not out:
        sources = sorted({r.task.source_kind for r in mine})
        picked = ", ".join(f"{name}@{wanted(s)}" for s in sources)
        bare = "" if "@" in text else f" (what a bare {name!r} runs on their data)"
        raise DataError(f"no records of {picked}{bare}; records of "
                        f"{', '.join(f'{name}@{v}' for v in held)}"
                        + (f"; registered: {', '.join(f'{name}@{v}' for v in registered)}"
                           if registered else ""))
    return out


def main(args: argparse.Namespace) -> int:
    if len(args.method) != 2:
        raise ConfigError(f"give exactly two --method (A, then B), got {len(args.method)}")
    results = args.results or default_results_dir()
    records, problems = load_records(results)
    for problem in problems[:3]:
        print(f"safl-bench: warning: skipped record {problem}", file=sys.stderr)
    if len(problems) > 3:
        print(f"safl-bench: warning: ... and {len(problems) - 3} more records skipped",
              file=sys.stderr)
    a, b = (_pick(records, m) for m in args.method)
    if args.task:
        from safl_bench.run.runner import resolve_tasks

        wanted = resolve_tasks(args.task, source=args.source)
    else:
        wanted = sorted(set(a) & set(b))
    measures = args.measure or list(DEFAULT_MEASURES)
    label_a, label_b = args.method
    print(f"A = {label_a}, B = {label_b}, {args.mode} matching, records in {results}; means over "
          "the seeds both have, 95 % intervals over seeds and queries (values in %, AUC and F1 x 100)")
    for task_id in wanted:
        shared = sorted(set(a.get(task_id, {})) & set(b.get(task_id, {})))
        if not shared:
            print(f"{task_id}: no seed with records of both methods; run them first")
            continue
        only = sorted((set(a.get(task_id, {})) | set(b.get(task_id, {}))) - set(shared))
        sides: list[list[Outcomes]] = []
        for side in (a, b):
            outcomes = []
            for seed in shared:
                result = side[task_id][seed].results.get(args.mode)
                if result is None or result.queries is None:
                    raise DataError(f"{task_id} seed {seed}: a record holds no per-query outcomes "
                                    "(metrics version 1); recompute it with `safl-bench run --force`")
                outcomes.append(result.queries.outcomes())
            sides.append(outcomes)
        sa, sb = sample(sides[0]), sample(sides[1])  # one bootstrap per side, paired resamples
        ia, ib, diff = sa.intervals(), sb.intervals(), sa.minus(sb)
        seeds = ", ".join(map(str, shared)) + (f" (not compared: {', '.join(map(str, only))})"
                                               if only else "")
        print(f"\n{task_id}  seeds {seeds}")
        rows = [("measure", "A", "B", "A - B")]
        wins: list[str] = []
        losses: list[str] = []
        ties: list[str] = []
        for name in measures:
            if name not in diff:
                continue
            rows.append((name, ia[name].format(100), ib[name].format(100), diff[name].format(100)))
            d = diff[name]
            (wins if d.excludes_zero() and d.mean > 0 else
             losses if d.excludes_zero() and d.mean < 0 else ties).append(name)
        widths = [max(len(r[i]) for r in rows) for i in range(4)]
        for row in rows:
            print("  " + "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip())
        verdict = "; ".join(part for part in (
            f"A better on {', '.join(wins)}" if wins else "",
            f"B better on {', '.join(losses)}" if losses else "",
            f"tied on {', '.join(ties)}" if ties else "") if part)
        print(f"  verdict: {verdict}")
    return 0
