"""Parallel runs (issue 8): local worker processes and a local Ray cluster give exactly the
records of a serial run; a worker killed mid-cell leaves no partial record and a rerun
completes the grid; only the main process writes records and takes timings."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import write_kitti
from parallel_methods import KillOnMarker
from test_runner import options, register_tiny

from safl_bench import mapcache, runner
from safl_bench.cli import main
from safl_bench.errors import ConfigError
from safl_bench.evaluation import EvaluationConfig
from safl_bench.mapbuild import select_frames
from safl_bench.mapconfig import MapConfig
from safl_bench.matching import MatcherConfig
from safl_bench.method_registry import make_method
from safl_bench.noise import CLEAN, Condition
from safl_bench.parallel import Parallel, run_jobs
from safl_bench.sources import kitti_source

TASKS = ("Test/ParA-T1R1-v0", "Test/ParA-T5R1-v0", "Test/ParA-T1R2-v0")


@pytest.fixture
def grid(kitti_root: Path, safl_home: Path) -> Iterator[tuple[str, ...]]:
    yield from register_tiny(TASKS)


def _results(outcomes: list[runner.CellOutcome]) -> dict[str, object]:
    """Everything of the records but when and how fast they ran."""
    out = {}
    for o in outcomes:
        assert o.status == "computed", (o.task_id, o.message)
        data = json.loads(o.path.read_text())
        out[str(o.path.relative_to(o.path.parents[2]))] = (data["results"], data["task"], data["method"], data["matcher"])
    return out


def test_local_workers_give_the_serial_records(grid, kitti_root, tmp_path):
    sad = make_method("sad")
    serial = runner.run_cells(sad, grid, options(kitti_root, tmp_path / "serial"))
    par = runner.run_cells(sad, grid, options(kitti_root, tmp_path / "par"), parallel=Parallel(workers=2))
    assert _results(serial) == _results(par)
    how = {o.record.timings.how_run for o in par if o.record is not None}
    assert len(how) == 1 and how.pop().startswith(
        "evaluated on 2 local worker processes; timed afterwards in the main process, one cell at a "
        "time, pinned to CPU")
    again = runner.run_cells(sad, grid, options(kitti_root, tmp_path / "par"), parallel=Parallel(workers=2))
    assert {o.status for o in again} == {"reused"}


def test_one_cell_spreads_its_describing_and_matching_over_the_workers(grid, kitti_root, tmp_path,
                                                                      monkeypatch):
    """A grid of fewer cells than workers (the long drive is one cell) is evaluated here, its
    describing in chunks and the exact matcher's query spans on the workers: the serial
    record, field for field, and the record says where it ran."""
    from safl_bench.common import parallel as parallel_module
    from safl_bench.evaluation import cell as cell_module

    monkeypatch.setattr(cell_module, "SPREAD_FRAMES", 1)  # the tiny cell's 24 views spread
    monkeypatch.setattr(runner, "_local_cores", lambda: 1)  # as if the workers were elsewhere
    monkeypatch.setenv("SAFL_BLOCK_MB", "0.0001")  # one query row a block: 12 blocks, 4 spans
    calls: list[str] = []

    real_run = parallel_module.run_jobs

    def counted(fn, jobs, par, **kw):
        calls.append(f"{fn.__name__} x{len(jobs)}")
        return real_run(fn, jobs, par, **kw)

    monkeypatch.setattr(parallel_module, "run_jobs", counted)
    monkeypatch.setattr(runner, "run_jobs", counted)
    sad = make_method("sad")
    one = grid[:1]
    serial = runner.run_cells(sad, one, options(kitti_root, tmp_path / "serial"))
    assert calls == []
    par = runner.run_cells(sad, one, options(kitti_root, tmp_path / "par"), parallel=Parallel(workers=2))
    assert _results(serial) == _results(par)
    # database, then queries, in chunks of 3 views (two a worker); the matcher in 4 spans
    assert calls == ["_describe_job x4", "_describe_job x4", "_span_job x4"]
    record = par[0].record
    assert record is not None and "describing and matching spread over 2 local worker processes" \
        in record.timings.how_run
    calls.clear()
    monkeypatch.setattr(runner, "_local_cores", lambda: 2)  # 2 workers on 2 cores: one job
    runner.run_cells(sad, one, options(kitti_root, tmp_path / "here"), parallel=Parallel(workers=2))
    assert calls == ["evaluate_cell x1"]


def test_a_grid_of_methods_and_seeds_is_one_queue_with_the_serial_records(grid, kitti_root, tmp_path):
    methods = [make_method("sad"), KillOnMarker()]  # no marker: a plain row/column profile
    serial = runner.run_grid(methods, grid[:2], options(kitti_root, tmp_path / "serial"), seeds=[0, 5])
    par = runner.run_grid(methods, grid[:2], options(kitti_root, tmp_path / "par"), seeds=[0, 5],
                          parallel=Parallel(workers=2))
    assert [(o.method, o.seed, o.task_id) for o in par] == [
        (m, seed, t) for m in ("sad", "kill_on_marker") for seed in (0, 5) for t in grid[:2]]
    assert _results(serial) == _results(par) and len(_results(par)) == 8
    table = runner.summary_table(par)
    assert table.splitlines()[0].split()[:3] == ["method", "task", "seeds"]
    with pytest.raises(ConfigError, match="one method twice"):
        runner.run_grid([make_method("sad"), make_method("sad", size=16)], grid, options(kitti_root, tmp_path))


def test_a_killed_worker_loses_only_its_cell_and_a_rerun_completes(grid, kitti_root, tmp_path):
    marker = tmp_path / "kill"
    marker.write_text("")
    results = tmp_path / "res"
    always = KillOnMarker(marker=str(marker), parent_pid=os.getpid())
    dead = runner.run_cells(always, grid, options(kitti_root, results), parallel=Parallel(workers=2))
    assert [o.status for o in dead] == ["failed"] * 3 and all("died" in o.message for o in dead)
    assert not list(results.rglob("*")) or not list(results.rglob("*.json"))  # nothing partial
    marker.unlink()
    rerun = runner.run_cells(always, grid, options(kitti_root, results), parallel=Parallel(workers=2))
    assert [o.status for o in rerun] == ["computed"] * 3

    # one worker dies: the pool breaks, the cells it took down are rerun one by one and complete
    marker.write_text("")
    once = KillOnMarker(marker=str(marker), parent_pid=os.getpid(), once=True)
    survived = runner.run_cells(once, grid, options(kitti_root, tmp_path / "once"), parallel=Parallel(workers=2))
    assert not marker.exists() and [o.status for o in survived] == ["computed"] * 3


def test_an_interrupted_parallel_run_keeps_its_evaluated_cells(grid, kitti_root, tmp_path, monkeypatch):
    """Cells evaluated on workers are kept on disk as they come back: a run interrupted before
    timing them (Ctrl-C) loses nothing, and the rerun times them without evaluating again."""
    sad = make_method("sad")
    serial = runner.run_cells(sad, grid, options(kitti_root, tmp_path / "serial"))
    results = tmp_path / "par"
    real_time_describe = runner.time_describe

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "time_describe", interrupted)
    with pytest.raises(KeyboardInterrupt):
        runner.run_cells(sad, grid, options(kitti_root, results), parallel=Parallel(workers=2))
    assert len(list(results.rglob("*.evaluated"))) == 3 and not list(results.rglob("*.json"))

    monkeypatch.setattr(runner, "time_describe", real_time_describe)
    monkeypatch.setattr(runner, "evaluate_cell", None)  # evaluating again would fail
    notes: list[str] = []
    resumed = runner.run_cells(sad, grid, options(kitti_root, results), parallel=Parallel(workers=2),
                               log=notes.append)
    assert _results(serial) == _results(resumed)
    assert any("3 cell(s) evaluated by an interrupted run" in n for n in notes)
    assert not list(results.rglob("*.evaluated"))
    assert all("evaluated on 2 local worker processes" in o.record.timings.how_run  # type: ignore[union-attr]
               for o in resumed)


def test_an_evaluated_cell_of_other_settings_is_evaluated_again(grid, kitti_root, tmp_path, monkeypatch):
    sad = make_method("sad")
    results = tmp_path / "par"
    monkeypatch.setattr(runner, "time_describe", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt))
    with pytest.raises(KeyboardInterrupt):
        runner.run_cells(sad, grid[:1], options(kitti_root, results), parallel=Parallel(workers=2))
    monkeypatch.undo()
    (pending,) = results.rglob("*.evaluated")
    other = options(kitti_root, results, evaluation=EvaluationConfig(sequence=MatcherConfig(ds=5)))
    again = runner.run_cells(sad, grid[:1], other)  # serially: the stale evaluation is not used
    assert again[0].status == "computed" and again[0].record.matcher["sequence"]["ds"] == 5  # type: ignore[union-attr]
    pending.write_text("{not json")
    notes: list[str] = []
    redo = runner.run_cells(sad, grid[:1], options(kitti_root, results), log=notes.append)
    assert redo[0].status == "computed" and any("evaluating the cell again" in n for n in notes)


def test_run_jobs_reports_errors_per_job():
    results = run_jobs(int, [("1",), ("x",), ("3",)], Parallel(workers=2))
    assert [r.value for r in results] == [1, None, 3]
    assert results[1].error is not None and "invalid literal" in results[1].error
    with pytest.raises(ConfigError, match="workers"):
        Parallel(workers=0)
    with pytest.raises(ConfigError, match="not both"):
        Parallel(workers=2, ray_address="auto")


def test_no_ray_cluster_to_join_is_a_clear_error(monkeypatch):
    ray = pytest.importorskip("ray")
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    assert not ray.is_initialized()
    with pytest.raises(ConfigError, match=r"--ray auto: cannot join the Ray cluster \(start one"):
        Parallel(ray_address="auto").slots()


def test_chunked_map_building_gives_the_serial_maps(kitti_copy, safl_home):
    """Two sequences' chunks in one queue on 2 workers: the same views as serial map building,
    whichever way the cache file was written, and a parallel cache file is reused serially."""
    write_kitti(kitti_copy, "01", n=9, seed=1)
    source = kitti_source(kitti_copy)
    frames = {name: select_frames(len(source.sequence(name)), 1) for name in ("00", "01")}
    conds = [CLEAN, Condition(5.0, 1.0)]
    kw = dict(conditions=conds, seed=0, kinds=("topview", "points"), progress=False)
    serial = mapcache.prepare_sequences(source, frames, MapConfig(size=32), **kw)
    expected = {(name, key): mapcache._load(path, key[1]) for name, files in serial.items() for key, path in files.items()}
    for files in serial.values():
        for path in files.values():
            path.unlink()
    chunked = mapcache.prepare_sequences(source, frames, MapConfig(size=32), parallel=Parallel(workers=2), **kw)
    assert set(chunked) == {"00", "01"}
    for name, files in chunked.items():
        for key, path in files.items():
            got = mapcache._load(path, key[1])
            if key[1] == "topview":
                assert (got == expected[name, key]).all(), (name, key)
            else:
                assert all((a == b).all() for a, b in zip(got, expected[name, key], strict=True)), (name, key)
    stamps = {path: path.stat().st_mtime_ns for files in chunked.values() for path in files.values()}
    views = mapcache.load_views(source, "01", MapConfig(size=32), frames=frames["01"], condition=conds[1], seed=0,
                                progress=False)
    assert (views == expected["01", (conds[1], "topview")]).all()
    assert all(path.stat().st_mtime_ns == t for path, t in stamps.items())  # reused, not rebuilt


def test_ray_cluster_gives_the_serial_records(grid, kitti_root, safl_home, tmp_path, monkeypatch):
    """A local Ray cluster started here (2 CPUs) runs the grid to the serial run's records, and
    one cell alone with its describing and matching spread over the cluster to the same
    record; a Ray worker killed mid-cell fails its own cell only, leaves no partial record, and
    the rerun completes the grid."""
    from safl_bench.evaluation import cell as cell_module

    ray = pytest.importorskip("ray")
    here = str(Path(__file__).parent)  # the workers import parallel_methods from here
    path = os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH", "")) if p)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"SAFL_HOME": str(safl_home), "PYTHONPATH": path}})
    try:
        sad = make_method("sad")
        serial = runner.run_cells(sad, grid, options(kitti_root, tmp_path / "serial"))
        par = runner.run_cells(sad, grid, options(kitti_root, tmp_path / "ray"), parallel=Parallel(ray_address="auto"))
        assert _results(serial) == _results(par)
        assert par[0].record is not None and par[0].record.timings.how_run.startswith(
            "evaluated on Ray cluster (auto); timed afterwards in the main process")
        with monkeypatch.context() as m:
            m.setattr(cell_module, "SPREAD_FRAMES", 1)
            m.setattr(runner, "_local_cores", lambda: 1)
            m.setenv("SAFL_BLOCK_MB", "0.0001")
            one = runner.run_cells(sad, grid[:1], options(kitti_root, tmp_path / "ray-one"),
                                   parallel=Parallel(ray_address="auto"))
        assert _results(one) == _results(serial[:1])
        assert one[0].record is not None and "spread over Ray cluster (auto)" in \
            one[0].record.timings.how_run

        marker = tmp_path / "kill"
        marker.write_text("")
        results = tmp_path / "killed"
        once = KillOnMarker(marker=str(marker), parent_pid=os.getpid(), once=True)
        first = runner.run_cells(once, grid, options(kitti_root, results), parallel=Parallel(ray_address="auto"))
        assert not marker.exists()  # a worker claimed it and died
        dead = [o for o in first if o.status == "failed"]
        assert len(dead) == 1 and "died" in dead[0].message
        assert not dead[0].path.exists() and not list(results.rglob("*.evaluated"))
        assert sorted(o.status for o in first) == ["computed", "computed", "failed"]
        rerun = runner.run_cells(once, grid, options(kitti_root, results), parallel=Parallel(ray_address="auto"))
        assert sorted(o.status for o in rerun) == ["computed", "reused", "reused"]
    finally:
        ray.shutdown()


def test_cli_workers_and_bad_values(grid, kitti_root, tmp_path, capsys):
    argv = ["run", "--method", "sad", "--task", grid[0], "--kitti-root", str(kitti_root),
            "--results", str(tmp_path), "--quiet"]
    assert main([*argv, "--workers", "2"]) == 0
    assert "computed" in capsys.readouterr().out
    assert main([*argv, "--seed", "0", "--seed", "3", "--workers", "2"]) == 0
    lines = capsys.readouterr().out.splitlines()
    row = next(ln for ln in lines if ln.startswith(grid[0]))
    assert lines[1].split()[:2] == ["task", "seeds"] and row.split()[1] == "0,3"
    assert "reused 1" in row and "computed 1" in row
    assert main([*argv, "--method", "bigan", "--param", "epochs=1"]) == 2
    assert "--param apply to one method" in capsys.readouterr().err
    assert main([*argv, "--workers", "0"]) == 2
    assert main([*argv, "--workers", "2", "--ray", "auto"]) == 2
    assert "not both" in capsys.readouterr().err


def test_bench_parallel_prints_the_speed_up_and_the_per_cell_times(kitti_root, safl_home, tmp_path, capsys):
    out = tmp_path / "bench.json"
    argv = ["bench", "parallel", "--kitti-root", str(kitti_root), "--ray", "none", "--quiet"]
    assert main([*argv, "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "12 frames x 13 conditions: 1 worker" in text and "-> speed-up" in text
    assert "SAD, 12 cells with cached maps, seconds per cell: serial" in text
    figures = json.loads(out.read_text())
    assert figures["map_building"]["speedup"] > 0 and figures["cells"]["local_s_per_cell"] > 0
    assert os.environ["SAFL_HOME"] == str(safl_home)  # the scratch home is gone again
    assert not list(safl_home.rglob("*.npz"))  # nothing built into the user's cache
    assert main([*argv, "--workers", "1"]) == 2
    assert main([*argv, "--sequence", "07"]) == 2
    assert "07" in capsys.readouterr().err
