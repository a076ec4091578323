"""`safl-bench data resampling`: resampled against re-rendered queries (analysis.resampling)."""

from __future__ import annotations

import csv
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from safl_bench.analysis.resampling import ARMS, masked_queries, resampled_queries
from safl_bench.cli import main
from safl_bench.tasks import register, unregister
from safl_bench.views.mapconfig import MapConfig
from safl_bench.views.resample import coverage_masks

TASK = "Test/TinyResampling-T5R1-v0"


def test_resampled_queries_without_noise_are_the_clean_views() -> None:
    clean = np.random.default_rng(0).random((3, 16, 16), dtype=np.float32)
    assert np.array_equal(resampled_queries(clean, np.zeros((3, 3)), 1.25), clean)
    assert np.array_equal(masked_queries(clean, np.zeros((3, 3)), 1.25), clean)


def test_masked_queries_are_empty_exactly_where_the_resampled_ones_are() -> None:
    views = np.random.default_rng(1).random((2, 16, 16), dtype=np.float32) + 0.5  # no zeros
    offsets = np.array([[2.5, 0.0, 0.0], [0.0, -1.25, 0.3]])  # 2 px forward; 1 px right, turned
    resampled = resampled_queries(views, offsets, 1.25)
    masked = masked_queries(views, offsets, 1.25)
    assert np.array_equal(masked == 0, resampled == 0)
    assert (masked[0, :2] == 0).all() and (masked[0, 2:] == views[0, 2:]).all()  # ahead: empty
    assert coverage_masks(16, offsets, 1.25)[1].mean() < 1.0


@pytest.fixture
def tiny_task(kitti_root: Path, safl_home: Path) -> Iterator[str]:
    register(TASK, source="kitti", sequence="00", condition="T5R1", step=1,
             map_config=MapConfig(size=32), n_seeds=1)
    yield TASK
    unregister(TASK)


def test_command_writes_its_report_and_reuses_its_cells(tiny_task, kitti_root, tmp_path, capsys) -> None:
    out = tmp_path / "report"
    argv = ["data", "resampling", "--out", str(out), "--task", tiny_task, "--kitti-root",
            str(kitti_root), "--method", "sad", "--matcher-preset", "paper", "--matcher", "ds=3",
            "--quiet"]
    assert main(argv) == 0
    rows = list(csv.DictReader((out / "resampling.csv").open()))
    assert {r["measure"] for r in rows} >= {"recall_at_100_precision", "auc"}
    assert all(r["method"] == "sad@1" and r["condition"] == "T5R1" for r in rows)
    assert 0 < float(rows[0]["coverage"]) < 1  # a 5 m shift empties part of a 32 x 2.5 m view
    config = json.loads((out / "config.json").read_text())
    assert config["command"].startswith("safl-bench data resampling --out")
    assert config["matcher"]["ds"] == 3 and config["arms"] == list(ARMS)
    report = (out / "resampling.md").read_text()
    assert "resampled − rerendered" in report and "| sad@1 | T5R1 |" in report
    cells = sorted((out / "cells").rglob("*.npz"))
    assert len(cells) == len(ARMS)
    stamps = [p.stat().st_mtime_ns for p in cells]
    capsys.readouterr()
    assert main(argv) == 0  # every cell reused: same files, same report
    assert [p.stat().st_mtime_ns for p in sorted((out / "cells").rglob("*.npz"))] == stamps
    assert (out / "resampling.md").read_text() == report


@pytest.mark.parametrize("extra, words", [
    (["--task", "SAFL/BEVKITTI00-T1R1-v0"], "resampled top-view images already"),
    (["--task", "SAFL/Synth00-Revisit-v4"], "needs the paper protocol"),
    (["--task", "SAFL/Synth00-T0R0-v4"], "needs the paper protocol"),
    (["--method", "no_such_method"], "no_such_method"),
    (["--matcher-preset", "nope"], "nope"),
])
def test_bad_input_is_one_line(extra, words, tmp_path, capsys) -> None:
    assert main(["data", "resampling", "--out", str(tmp_path / "o"), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and len(err.splitlines()) == 1


def test_an_out_that_is_a_file_is_one_line(tmp_path, capsys) -> None:
    path = tmp_path / "file"
    path.write_text("x")
    assert main(["data", "resampling", "--out", str(path), "--task", "SAFL/Synth00-T1R1-v4",
                 "--seed", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert str(path) in err and len(err.splitlines()) == 1
