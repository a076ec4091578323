"""Does the synthetic default rank the methods as real KITTI does? Measured from result records.

The main job runs the synthetic default, so its order of the methods is what most users see
first; this module compares it with real KITTI's on the same protocol, in one matching mode and
one measure, from the records alone (no images, no rerun). Choices, and why:

* **Sides.** The paper protocol (the main job's): the twelve noise conditions of synthetic
  sequence 00 against those of real KITTI 00 (BEVPlace's top views; the current task versions).
  The revisit protocol: synthetic 00's revisit task against each of real 00, 05 and 06, one
  comparison each. Real 02 is left out: it is the training sequence of the real-KITTI weights
  of BiGAN and Stable-AFL, whose rows there measure memory, not what the data asks.
* **Methods.** Every method (``name@version``) with a record of every seed of every task of
  both sides, in the matching mode, none of them marked seen in training; the others are named
  with the reason (`Comparison.left_out`). Each side's records hold the weights `safl-bench
  run` picks for that source (a learned method's synthetic weights on the default, its
  real-KITTI ones on KITTI): `Comparison.weights` names them, since the order then compares two
  trainings as well as two data sets.
* **A side's value** is the mean over its tasks of each cell's mean over its seeds (the tables'
  numbers, averaged over the conditions as the issue's and the README's summaries are); its
  bootstrap replicates are the same mean of the cells' replicates (`uncertainty.sample`: seeds,
  then blocks of queries, 1000 replicates from a fixed seed). The cells of one task share their
  resamples, so two methods' replicates on a side are paired.
* **Repeated runs** (`records.is_repeat`: an unseedable method, such as MapClosures, run 3 times
  on a task where nothing is random) are that cell's runs, as the tables read them: they do not
  count against the task's seeds, and the cell's value and replicates are over its runs (the
  runs drawn as seeds), so their spread widens its intervals. Such a cell's replicates draw
  other query blocks than a one-run cell's, so its pairs are not paired on the queries (their
  intervals are then wider wherever two methods miss the same queries).
* **tau** is Kendall's tau-b of the methods' values, synthetic against real: defined whenever
  each side has two methods that differ (ties count as tau-b counts them). Its 95 % interval
  is the percentile interval of tau-b over the replicates, replicate r ranking every method by
  its r-th replicate on each side (the two sides' resamples are independent: other queries).
  An interval that excludes 0 says the orders agree (or disagree) beyond the noise.
* **Pairs beyond the noise.** Each pair's paired difference on each side with its 95 %
  interval; a pair is *resolved* on a side when that interval excludes 0. `Comparison.agree`
  and `.disagree` count the pairs resolved on both sides the same or the opposite way, which
  says which pairs the disagreement is made of.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from safl_bench.evaluation.uncertainty import LEVEL, Interval, sample
from safl_bench.results.records import ResultRecord, is_repeat, seed_outcomes

#: The measures compared, by matching mode (the headline's Recall@1 in both modes).
MEASURES = (("sequence", "recall_at_1"), ("single_frame", "recall_at_1"))
#: The real sequences compared on the revisit protocol (02 trains the real-KITTI weights).
REVISIT_REAL = ("00", "05", "06")
SYNTHETIC_SEQUENCE = "00"
PAPER_REAL = ("00",)


@dataclass(frozen=True)
class Side:
    """One side of a comparison: a label ("synthetic 00", "real 05") and its task ids."""

    label: str
    tasks: tuple[str, ...]


@dataclass(frozen=True)
class Pair:
    """Two methods (`first` < `second` by name): first minus second on each side, with the
    order that survives the noise there (1 first better, -1 second better, 0 tied)."""

    first: str
    second: str
    synthetic: Interval
    real: Interval

    @staticmethod
    def order(iv: Interval) -> int:
        return 0 if not iv.excludes_zero() else (1 if iv.mean > 0 else -1)

    @property
    def verdict(self) -> str:
        """'agree', 'disagree', 'resolved on one side' or 'tied on both'."""
        a, b = self.order(self.synthetic), self.order(self.real)
        if a and b:
            return "agree" if a == b else "disagree"
        return "resolved on one side" if a or b else "tied on both"


@dataclass
class Comparison:
    """One protocol, matching mode and measure: the methods' values on both sides, tau with its
    interval, and the pairs (module docstring)."""

    protocol: str
    matching: str
    measure: str
    synthetic: Side
    real: Side
    values: dict[str, dict[str, Interval]] = field(default_factory=dict)  # method -> side label -> value
    tau: Interval | None = None
    pairs: list[Pair] = field(default_factory=list)
    left_out: dict[str, str] = field(default_factory=dict)  # method -> why
    weights: dict[str, dict[str, str]] = field(default_factory=dict)  # method -> side label -> weights

    @property
    def methods(self) -> list[str]:
        return sorted(self.values)

    def order(self, side: Side) -> list[str]:
        """The methods best first on `side`."""
        return sorted(self.values, key=lambda m: (-self.values[m][side.label].mean, m))

    @property
    def agree(self) -> int:
        return sum(p.verdict == "agree" for p in self.pairs)

    @property
    def disagree(self) -> int:
        return sum(p.verdict == "disagree" for p in self.pairs)

    @property
    def title(self) -> str:
        mode = "sequence" if self.matching == "sequence" else "single-frame"
        return (f"{self.protocol} protocol, {mode} {MEASURE_NAMES.get(self.measure, self.measure)}: "
                f"{self.synthetic.label} against {self.real.label}")

    def to_json(self) -> dict[str, Any]:
        def iv(i: Interval | None) -> dict[str, float] | None:
            return None if i is None else {"value": i.mean, "low": i.low, "high": i.high}

        return {
            "protocol": self.protocol, "matching": self.matching, "measure": self.measure,
            "synthetic": {"label": self.synthetic.label, "tasks": list(self.synthetic.tasks)},
            "real": {"label": self.real.label, "tasks": list(self.real.tasks)},
            "values": {m: {s: iv(v) for s, v in per.items()} for m, per in sorted(self.values.items())},
            "order": {side.label: self.order(side) for side in (self.synthetic, self.real)},
            "tau": iv(self.tau),
            "pairs": [{"first": p.first, "second": p.second, "synthetic": iv(p.synthetic),
                       "real": iv(p.real), "verdict": p.verdict} for p in self.pairs],
            "agree": self.agree, "disagree": self.disagree,
            "left_out": dict(sorted(self.left_out.items())),
            "weights": {m: dict(w) for m, w in sorted(self.weights.items())},
        }


MEASURE_NAMES = {"recall_at_1": "Recall@1", "recall_at_100_precision": "R@100%P", "f1_max": "F1max"}


def tau_b(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Kendall's tau-b of the last axis of `x` against `y` ((..., n) each, n methods): over
    the pairs, (concordant - discordant) / sqrt(pairs untied in x * pairs untied in y); NaN
    where either side ties every pair (no order to correlate)."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    i, j = np.triu_indices(x.shape[-1], k=1)
    sx, sy = np.sign(x[..., i] - x[..., j]), np.sign(y[..., i] - y[..., j])
    nx, ny = np.abs(sx).sum(axis=-1), np.abs(sy).sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (sx * sy).sum(axis=-1) / np.sqrt(nx * ny)
    return np.where((nx > 0) & (ny > 0), out, np.nan)


def weights_label(params: dict[str, Any]) -> str:
    """'file sha256[:12]' of the weights in a record's method parameters ('' when none)."""
    w = params.get("weights")
    if not isinstance(w, dict):
        return ""
    if not w.get("sha256"):
        return str(w.get("source", ""))  # "untrained"
    return f"{Path(str(w.get('path', '?'))).name} {str(w['sha256'])[:12]}"


def _cells(records: Sequence[ResultRecord]) -> dict[tuple[str, str], list[ResultRecord]]:
    """{(method@version, task id): its records, by seed}."""
    cells: dict[tuple[str, str], list[ResultRecord]] = defaultdict(list)
    for r in records:
        cells[(f"{r.method.name}@{r.method.version}", r.task.id)].append(r)
    return {k: sorted(v, key=lambda r: r.seed) for k, v in cells.items()}


def compare(records: Sequence[ResultRecord], protocol: str, synthetic: Side, real: Side,
            matching: str, measure: str) -> Comparison:
    """The comparison of `synthetic` against `real` in `matching` mode and `measure`, over the
    methods with every cell of both sides (module docstring)."""
    from safl_bench.tasks import spec

    cells = _cells(records)
    out = Comparison(protocol, matching, measure, synthetic, real)
    replicates: dict[str, dict[str, np.ndarray]] = {}
    for method in sorted({m for m, _ in cells}):
        per_side: dict[str, Interval] = {}
        reps: dict[str, np.ndarray] = {}
        used: dict[str, str] = {}
        why = ""
        for side in (synthetic, real):
            points, values, seeds, queries = [], [], 0, 0
            for task in side.tasks:
                got = cells.get((method, task))
                if not got:
                    why = f"no record on {task}"
                    break
                want = spec(task).seeds
                seeded = [r.seed for r in got if not is_repeat(r)]
                if seeded != list(want):
                    why = f"seeds {seeded} of {list(want)} on {task}"
                    break
                if any(r.seen_in_training for r in got):
                    why = f"seen in training on {task}"
                    break
                outcomes = seed_outcomes(got, matching)
                if outcomes is None:
                    why = f"no per-query {matching} outcomes on {task}"
                    break
                s = sample(outcomes)
                points.append(s.points[measure])
                values.append(s.values[measure])
                seeds, queries = seeds + s.n_seeds, queries + s.n_queries
                used.setdefault(side.label, weights_label(got[0].method.params))
            if why:
                break
            rep = np.mean(values, axis=0)
            point = float(np.mean(points))
            reps[side.label] = rep
            per_side[side.label] = _interval(point, rep, seeds, queries)
        if why:
            out.left_out[method] = why
            continue
        out.values[method] = per_side
        replicates[method] = reps
        if len(set(used.values())) > 1:
            out.weights[method] = used
    methods = out.methods
    if len(methods) >= 2:
        xs = np.array([out.values[m][synthetic.label].mean for m in methods])
        ys = np.array([out.values[m][real.label].mean for m in methods])
        point = float(tau_b(xs, ys))
        rx = np.stack([replicates[m][synthetic.label] for m in methods], axis=-1)
        ry = np.stack([replicates[m][real.label] for m in methods], axis=-1)
        out.tau = _interval(point, tau_b(rx, ry), len(methods), len(methods))
        for a_i, a in enumerate(methods):
            for b in methods[a_i + 1:]:
                sides = []
                for side in (synthetic, real):
                    va, vb = out.values[a][side.label], out.values[b][side.label]
                    diff = replicates[a][side.label] - replicates[b][side.label]
                    sides.append(_interval(va.mean - vb.mean, diff, va.n_seeds, va.n_queries))
                out.pairs.append(Pair(a, b, sides[0], sides[1]))
    return out


def _interval(point: float, values: np.ndarray, n_seeds: int, n_queries: int) -> Interval:
    """`point` with the percentile interval of the finite `values` (NaN bounds when none)."""
    finite = values[np.isfinite(values)]
    if not finite.size or not math.isfinite(point):
        return Interval(point, float("nan"), float("nan"), n_seeds, n_queries)
    lo, hi = np.quantile(finite, [(1 - LEVEL) / 2, (1 + LEVEL) / 2])
    return Interval(point, float(lo), float(hi), n_seeds, n_queries)


def sides(protocol: str) -> list[tuple[Side, Side]]:
    """The (synthetic, real) sides compared on `protocol` ("paper" or "revisit")."""
    from safl_bench.tasks.builtin import paper_id, revisit_id
    from safl_bench.views.noise import PAPER_CONDITIONS

    if protocol == "paper":
        syn = Side(f"synthetic {SYNTHETIC_SEQUENCE}",
                   tuple(paper_id("synth", SYNTHETIC_SEQUENCE, c) for c in PAPER_CONDITIONS))
        return [(syn, Side(f"real {s}", tuple(paper_id("bev", s, c) for c in PAPER_CONDITIONS)))
                for s in PAPER_REAL]
    if protocol == "revisit":
        syn = Side(f"synthetic {SYNTHETIC_SEQUENCE}", (revisit_id("synth", SYNTHETIC_SEQUENCE),))
        return [(syn, Side(f"real {s}", (revisit_id("bev", s),))) for s in REVISIT_REAL]
    raise ValueError(f"no ranking comparison for protocol {protocol!r}; use 'paper' or 'revisit'")


def comparisons(records: Sequence[ResultRecord]) -> list[Comparison]:
    """Every comparison of the module docstring that has at least two methods: the paper
    protocol first (the main job's), then the revisit protocol; per side pair, each of
    `MEASURES`."""
    out = []
    for protocol in ("paper", "revisit"):
        for syn, real in sides(protocol):
            for matching, measure in MEASURES:
                c = compare(records, protocol, syn, real, matching, measure)
                if len(c.values) >= 2:
                    out.append(c)
    return out


TITLE = "Does the synthetic default rank the methods as real KITTI does?"
INTRO = (
    "The main job runs the synthetic default, so its order of the methods is the one most users "
    "see first. Each row compares it with real KITTI's on one protocol, matching mode and "
    "measure, from the records in this board: the methods' order on each side (best first; the "
    "value is the mean over the protocol's tasks, Recall@1 in %), Kendall's tau-b of the two "
    "orders with its 95 % bootstrap interval (over seeds and queries), and how many pairs of "
    "methods are resolved beyond the noise on both sides the same way (agree) or the opposite "
    "way (disagree). Learned methods run the weights `safl-bench run` picks for each source "
    "(synthetic-trained on the default, trained on real KITTI 02 on KITTI), so an order compares "
    "two trainings as well as two data sets. Real 02 is left out (the real weights' training "
    "sequence). `safl_bench.leaderboard.ranking` defines every choice.")


def _mode(matching: str) -> str:
    return "sequence" if matching == "sequence" else "single-frame"


def _order_text(c: Comparison, side: Side) -> str:
    return " > ".join(f"{m.split('@')[0]} {c.values[m][side.label].mean * 100:.1f}" for m in c.order(side))


def summary_rows(comps: Sequence[Comparison]) -> list[list[str]]:
    """The summary table's rows (header first): one per comparison."""
    rows = [["protocol", "matching", "real", "synthetic 00 order", "real order", "tau-b [95 %]",
             "pairs agree / disagree / one side / tied"]]
    for c in comps:
        counts = [sum(p.verdict == v for p in c.pairs)
                  for v in ("agree", "disagree", "resolved on one side", "tied on both")]
        rows.append([c.protocol, f"{_mode(c.matching)} {MEASURE_NAMES.get(c.measure, c.measure)}",
                     c.real.label.removeprefix("real "), _order_text(c, c.synthetic),
                     _order_text(c, c.real), "n/a" if c.tau is None else c.tau.format(1.0, 2),
                     " / ".join(str(n) for n in counts)])
    return rows


def notes(comps: Sequence[Comparison]) -> list[str]:
    """What the summary leaves out: methods without both sides, methods on mixed weights."""
    left: dict[str, set[str]] = defaultdict(set)
    mixed: set[str] = set()
    for c in comps:
        for m, why in c.left_out.items():
            left[m].add(why.split(" on ")[0])
        mixed |= set(c.weights)
    out = []
    if mixed:
        out.append("Ran on other weights on the two sources (synthetic-trained on the default, "
                   f"real-KITTI-trained on KITTI): {', '.join(sorted(mixed))}.")
    if left:
        out.append("Left out where a side lacks them: " + "; ".join(
            f"{m} ({', '.join(sorted(w))})" for m, w in sorted(left.items())) + ".")
    return out


def markdown(comps: Sequence[Comparison], level: int = 2) -> str:
    """The section: title, intro, the summary table and its notes."""
    rows = summary_rows(comps)
    lines = [f"{'#' * level} {TITLE}", "", INTRO, "",
             "| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
    lines += ["| " + " | ".join(r) + " |" for r in rows[1:]]
    lines += ["", *[f"- {n}" for n in notes(comps)]]
    return "\n".join(lines).rstrip("\n") + "\n"


def figure(comps: Sequence[Comparison], path: Path) -> None:
    """Per comparison of the paper protocol and of real 00's revisits: each method's value on
    the synthetic side against the real side, with both intervals (a point per method; the
    same order on both sides puts the points on a rising line)."""
    from safl_bench.leaderboard.figures import _new_figure, save_png

    shown = [c for c in comps if c.real.label == "real 00"] or list(comps)
    fig = _new_figure(4.6 * max(1, len(shown)), 4.8)
    axes = fig.subplots(1, max(1, len(shown)), squeeze=False)
    for ax, c in zip(axes[0], shown, strict=False):
        for m in c.methods:
            s, r = c.values[m][c.synthetic.label], c.values[m][c.real.label]
            ax.errorbar(100 * s.mean, 100 * r.mean,
                        xerr=[[100 * max(0.0, s.mean - s.low)], [100 * max(0.0, s.high - s.mean)]],
                        yerr=[[100 * max(0.0, r.mean - r.low)], [100 * max(0.0, r.high - r.mean)]],
                        fmt="o", capsize=3, label=m)
            ax.annotate(m.split("@")[0], (100 * s.mean, 100 * r.mean), fontsize=8,
                        xytext=(4, 4), textcoords="offset points")
        tau = "n/a" if c.tau is None else c.tau.format(1.0, 2)
        ax.set(title=f"{c.protocol}, {_mode(c.matching)} R@1\ntau-b {tau}",
               xlabel=f"{c.synthetic.label}: Recall@1 (%)", ylabel=f"{c.real.label}: Recall@1 (%)",
               xlim=(0, 100), ylim=(0, 100))
        ax.plot([0, 100], [0, 100], color="grey", lw=0.6)
        ax.grid(alpha=0.3)
    save_png(fig, path)
