"""What a careful user trips on (issue 47): options checked before any work, hints that carry the
user's own options and name the versions that have records, a warning printed once."""

from __future__ import annotations

from pathlib import Path

import pytest

from safl_bench.cli import main
from safl_bench.results.records import record_path
from safl_bench.tasks.registry import runnable_spec


def test_a_missing_data_folder_stops_run_before_any_work(capsys: pytest.CaptureFixture[str],
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("SAFL_BEV_ROOT", raising=False)
    monkeypatch.delenv("SAFL_BEV_ROT_ROOT", raising=False)
    assert main(["run", "--method", "sad", "--task", "SAFL/BEVKITTI00-Revisit-v0",
                 "--task", "SAFL/BEVKITTI02-Revisit-v0"]) == 2
    out, err = capsys.readouterr()
    assert out == ""  # nothing started
    assert err.strip() == ("safl-bench: error: task SAFL/BEVKITTI00-Revisit-v0 needs its data: "
                           "pass --bev-root DIR or set SAFL_BEV_ROOT (and 1 more tasks)")
    assert main(["run", "--method", "sad", "--task", "SAFL/BEVKITTI00-Revisit-RotQueries-v0",
                 "--bev-root", "somewhere"]) == 2
    assert "needs the rotated top-view images" in capsys.readouterr().err


def test_slam_names_the_version_that_has_a_record_and_keeps_the_options(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    task = "SAFL/BEVKITTI00-Revisit-v0"
    seed = runnable_spec(task).seed
    from safl_bench.methods.method import resolve_method

    picked = resolve_method("stable_afl", "bev").partition("@")[2]
    other = "1" if picked != "1" else "2"
    path = record_path(tmp_path, "stable_afl", other, task, seed)
    path.parent.mkdir(parents=True)
    path.write_text("{}")
    assert main(["slam", "--method", "stable_afl", "--task", task, "--results", str(tmp_path),
                 "--bev-root", "BEVPlace/data/KITTI"]) == 2
    err = capsys.readouterr().err
    assert f"no record of stable_afl@{picked} on {task}" in err
    assert f"stable_afl@{other} has one: pass --method stable_afl@{other}" in err
    assert f"--results {tmp_path}" in err and "--bev-root BEVPlace/data/KITTI" in err


def test_a_long_describe_prints_lines_in_a_log(monkeypatch: pytest.MonkeyPatch) -> None:
    from safl_bench.run import runner

    lines: list[str] = []
    frames = runner._CellFrames("SAFL/X frames", bar=False, log=lines.append)
    frames.expect(100)
    frames.advance(10)  # too soon for a line
    monkeypatch.setattr(runner._CellFrames, "LOG_EVERY_S", 0.0)
    frames.advance(40)
    assert lines == ["  SAFL/X frames: 50 of 100 described (50 %)"]


def test_a_long_step_that_reports_nothing_still_prints_lines_in_a_log() -> None:
    """Building views (or generating the synthetic data) says nothing itself; in a log the
    runner's heartbeat prints a line while it lasts, and stops with it."""
    import threading
    import time

    from safl_bench.common.progress import heartbeat

    lines: list[str] = []
    with heartbeat(lines.append, "preparing the views", every_s=0.02):
        time.sleep(0.3)
    said = len(lines)
    assert said >= 2 and all(line.startswith("  preparing the views: still working (") for line in lines)
    time.sleep(0.08)
    assert len(lines) == said and not [t for t in threading.enumerate() if t.name == "safl-heartbeat"]
    with heartbeat(None, "nothing", every_s=0.01):  # no log: no thread, no line
        time.sleep(0.03)
    from safl_bench.common.progress import report

    lines.clear()
    with heartbeat(lines.append, "preparing the views", every_s=0.02):
        report("maps L0: 6 of 20 chunks")  # how far the step got: on its next line
        time.sleep(0.1)
    assert lines and lines[-1].endswith(" s; maps L0: 6 of 20 chunks)")


def test_train_resolves_a_bare_name_as_run_does(capsys: pytest.CaptureFixture[str]) -> None:
    from safl_bench.methods.method import resolve_method

    # a parameter it does not have stops it after the version is picked, before any work
    assert main(["train", "--method", "stable_afl", "--set", "nope=1"]) == 2
    out = capsys.readouterr().out
    assert out.startswith(f"training {resolve_method('stable_afl', 'synth')}: a bare 'stable_afl' "
                          "is the version `run` runs on")


def test_timings_under_load_and_old_timings_are_marked() -> None:
    import dataclasses

    from record_factory import make_record

    from safl_bench.results.records import timed_under_load
    from safl_bench.run.runner import CellOutcome, summary_table

    base = make_record(seed=0)
    env = dataclasses.replace(base.environment, cpu_cores=2)
    idle = dataclasses.replace(base, environment=env,
                               timings=dataclasses.replace(base.timings, load_avg_1m=1.4))
    busy = dataclasses.replace(idle, timings=dataclasses.replace(base.timings, load_avg_1m=5.0))
    assert (timed_under_load(idle), timed_under_load(busy), timed_under_load(base)) == (False, True, None)
    table = summary_table([CellOutcome(busy.task.id, 0, "computed", Path("x"), busy,
                                       method="stable_afl", version="1")])
    assert "(loaded)" in table and "note: (loaded)" in table
    assert "timed when their record was made" not in table
    table = summary_table([CellOutcome(idle.task.id, 0, "reused", Path("x"), idle,
                                       method="stable_afl", version="1")])
    assert "(loaded)" not in table
    assert "timed when their record was made (2025-01-01), not now" in table


def test_a_loop_closure_row_without_closures_is_never_bold() -> None:
    from safl_bench.leaderboard import slam_table
    from safl_bench.slam.backend import BACKENDS
    from safl_bench.slam.cell import BackendResult, SlamResult

    def cell(method: str, ate: float, true: int, false: int) -> slam_table.SlamCell:
        results = tuple(SlamResult(
            method=method, task="SAFL/X-Revisit-v0", seed=0, settings={"mode": "sequence"},
            threshold=None if true + false == 0 else 0.5, threshold_rule="deployed on Y",
            drift={"level": "mid"}, n_poses=100, closures_true=true, closures_false=false,
            odometry_ate_m=ate, odometry_rpe_m=None, seconds=0.0, record_created="x",
            backends=[BackendResult(b, True, "", ate + 0.01 * s, None) for b in BACKENDS],
            slam_seed=s) for s in range(5))
        return slam_table.SlamCell(method, "SAFL/X-Revisit-v0", "sequence", results)

    # the no-closure row has the lowest ATE (it is the odometry), the others much higher
    md = slam_table.slam_markdown("t", [cell("none@1", 1.0, 0, 0), cell("a@1", 5.0, 10, 1),
                                        cell("b@1", 9.0, 10, 9)])
    assert md is not None
    row = next(line for line in md.splitlines() if line.startswith("| none@1"))
    assert "**" not in row and "≈" not in row
    assert "**5.0" in next(line for line in md.splitlines() if line.startswith("| a@1"))
