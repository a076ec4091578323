"""A small leaderboard for the web-page tests: real-KITTI (top-view image) revisit records of three
methods on 00 and 02 with two seeds, and synthetic paper-protocol records, all made by hand."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from record_factory import make_record

from safl_bench.matcher_presets import configure
from safl_bench.records import ResultRecord, write_record

BEV_LABEL = "KITTI top-view images"
#: F1max of the sequence matcher per (method, sequence, seed); single-frame is half of it.
F1 = {
    ("sad", "00", 0): 0.80, ("sad", "00", 1): 0.76, ("sad", "02", 0): 0.44, ("sad", "02", 1): 0.46,
    ("stable_afl", "00", 0): 0.70, ("stable_afl", "00", 1): 0.78, ("stable_afl", "02", 0): 0.40,
    ("stable_afl", "02", 1): 0.42,
    ("bevplace", "00", 0): 0.90, ("bevplace", "00", 1): 0.94, ("bevplace", "02", 0): 0.68,
    ("bevplace", "02", 1): 0.70,
}


def board_records() -> list[ResultRecord]:
    records = [
        make_record(method, protocol="revisit", sequence=seq, seed=seed, source_kind="bev",
                    source_label=BEV_LABEL, f1=f1, recall=f1 - 0.1, auc=0.95, recall_at_1=f1)
        for (method, seq, seed), f1 in sorted(F1.items())
    ]
    records += [make_record(m, condition=c, recall=r, auc=0.8)
                for m, r in (("sad", 0.2), ("stable_afl", 0.4)) for c in ("T1R1", "T5R1")]
    paper = configure("paper").to_dict()  # the matcher settings of a real run
    return [dataclasses.replace(r, matcher=paper) for r in records]


def write_board(root: Path) -> Path:
    """Write the records under root/leaderboard/records; returns the leaderboard directory."""
    out = root / "leaderboard"
    for record in board_records():
        write_record(out / "records", record)
    return out


def expected_f1(method: str, mode: str, sequence: str) -> float:
    """The mean F1max the table shows for (method, matching mode, sequence)."""
    scale = 1.0 if mode == "sequence" else 0.5
    return (F1[(method, sequence, 0)] + F1[(method, sequence, 1)]) / 2 * scale
