"""`safl-bench explain`: a cell's record redrawn as one PNG; a cell without a record is refused
with the run command that makes it."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from safl_bench import explain, matching, runner, tasks
from safl_bench.cli import main
from safl_bench.errors import DataError
from safl_bench.mapconfig import MapConfig
from safl_bench.method_registry import make_method

TINY = "Test/TinyExplain-T5R1-v0"


@pytest.fixture
def tiny_task(kitti_root: Path, safl_home: Path) -> Iterator[str]:
    tasks.register(TINY, source="kitti", sequence="00", condition="T5R1", step=1,
                   map_config=MapConfig(size=32))
    yield TINY
    tasks.unregister(TINY)


def options(kitti_root: Path, results: Path, **kw: object) -> runner.RunOptions:
    return runner.RunOptions(results_dir=results, kitti_root=str(kitti_root), progress=False,
                             timing_frames=3, timing_repeats=2, **kw)  # type: ignore[arg-type]


def test_explain_recomputes_the_record_and_writes_a_png(tiny_task, kitti_root, tmp_path, capsys):
    outcome = runner.run_cell(make_method("sad"), tiny_task, options(kitti_root, tmp_path))
    ex = explain.explain("sad", tiny_task, options(kitti_root, tmp_path), top=2)
    assert ex.record_path == outcome.path and ex.D.shape == (12, 12)
    np.testing.assert_array_equal(ex.enhanced, matching.enhanced_matrix(ex.D, ex.config.sequence))
    assert ex.metrics.recall_at_100 == pytest.approx(ex.recorded_recall)
    assert len(ex.worst) <= 2 and all(ex.status[i] == explain.WRONG for i in ex.worst)
    conf = ex.confidence
    assert all(conf[a] >= conf[b] for a, b in zip(ex.worst, ex.worst[1:], strict=False))
    assert (ex.true_index >= 0).all()  # paper protocol: every query has its own frame
    out = tmp_path / "fig" / "cell.png"
    assert main(["explain", "--method", "sad", "--task", tiny_task, "--kitti-root", str(kitti_root),
                 "--results", str(tmp_path), "--out", str(out), "--quiet"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    printed = capsys.readouterr().out
    assert "recall at 100 % precision" in printed and str(out) in printed


def test_explain_without_a_record_names_the_run_command(tiny_task, kitti_root, tmp_path, capsys):
    with pytest.raises(DataError, match="make it with: safl-bench run --method sad"):
        explain.explain("sad", tiny_task, options(kitti_root, tmp_path))
    assert main(["explain", "--method", "sad", "--task", tiny_task, "--seed", "3",
                 "--kitti-root", str(kitti_root), "--results", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("safl-bench: error: no record of sad@1")
    want = (f"safl-bench run --method sad --task {tiny_task} --seed 3 --results {tmp_path} "
            f"--kitti-root {kitti_root}")
    assert err[0].endswith(want)
    assert not list(tmp_path.glob("*.png"))


def test_run_command_quotes_what_needs_it() -> None:
    assert explain.run_command("sad", "SAFL/Synth00-T1R1-v4") == \
        "safl-bench run --method sad --task SAFL/Synth00-T1R1-v4"
    assert explain.run_command("sad", "X", results="my results") == \
        "safl-bench run --method sad --task X --results 'my results'"
