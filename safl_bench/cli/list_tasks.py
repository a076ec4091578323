"""`safl-bench list tasks`: the registered benchmark tasks as a table."""

from __future__ import annotations

import argparse

from safl_bench.tasks import SUITES, registry, suite
from safl_bench.tasks.spec import TaskSpec

HELP = "list the registered benchmark tasks (id, protocol, sequence, condition, source, scored queries)"

SOURCE_NAMES = {"synth": "synthetic default", "kitti": "KITTI", "bev": "top-view images"}
ROTATED_NAMES = {"queries": "queries", "both": "database and queries"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """--suite, --source, --fingerprints."""
    parser.add_argument(
        "--suite",
        default="all",
        choices=list(SUITES),
        help="only the tasks of a suite: " + "; ".join(f"{k}: {v}" for k, v in SUITES.items()),
    )
    parser.add_argument("--source", choices=list(SOURCE_NAMES), help="only tasks on this data")
    parser.add_argument(
        "--fingerprints", action="store_true", help="add each definition's fingerprint and details"
    )


def _row(spec: TaskSpec, details: bool) -> list[str]:
    condition = spec.condition.name if spec.protocol == "paper" else "-"
    scored = f"from query {spec.context_queries}" if spec.context_queries else "all queries"
    source = SOURCE_NAMES[spec.source] + (f", rotated {ROTATED_NAMES[spec.rotated]}" if spec.rotated else "")
    row = [spec.id, spec.protocol, spec.sequence, condition, source, scored]
    if details:
        window = "-" if spec.window_s is None else f"{spec.window_s:g}"
        radii = (
            f"{spec.tp_radius_m:g}"
            if spec.tp_radius_m == spec.fp_radius_m
            else f"{spec.tp_radius_m:g}/{spec.fp_radius_m:g}"
        )
        row += [str(spec.step), radii, window, spec.fingerprint]
    return row


def format_table(rows: list[list[str]], header: list[str]) -> str:
    """Left-aligned columns separated by two spaces, with a dashed rule under the header."""
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    lines = [
        "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip()
        for r in [header, *rows]
    ]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def main(args: argparse.Namespace) -> int:
    """Print the table; built-in tasks come first in suite order, then any others registered."""
    ids = suite(args.suite, source=args.source)
    if args.suite == "all":
        ids += [i for i, s in registry.items() if i not in ids and args.source in (None, s.source)]
    header = ["id", "protocol", "sequence", "condition", "source", "scored"]
    if args.fingerprints:
        header += ["step", "radius m (tp/fp)", "window s", "fingerprint"]
    print(format_table([_row(registry[i], args.fingerprints) for i in ids], header))
    print(
        f"\n{len(ids)} tasks. Synthetic tasks run out of the box; KITTI tasks need --kitti-root "
        "or SAFL_KITTI_ROOT, top-view tasks --bev-root or SAFL_BEV_ROOT (rotated ones also "
        "--bev-rot-root or SAFL_BEV_ROT_ROOT). Built-in paper protocol: database = clean maps of every 4th frame, queries = "
        "the same frames re-rendered with noise T{a}R{b}, true positive within 10 m; its first 10 queries, "
        "and those of BEVPlace's protocol, are context (matched, not scored). Built-in revisit: "
        "matches only to frames > 30 s older, true positive within 3 m, false positive beyond 20 m."
    )
    return 0
