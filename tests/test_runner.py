"""`safl-bench run` and the runner: records per cell, reuse, resume, recompute on change."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from conftest import write_kitti

from safl_bench import runner, tasks
from safl_bench.cli import main
from safl_bench.mapconfig import MapConfig
from safl_bench.method_registry import make_method
from safl_bench.metrics import METRICS_VERSION
from safl_bench.records import load_record

TASKS = ("Test/TinyRun-T1R1-v0", "Test/TinyRun-T5R1-v0")


def register_tiny(ids: tuple[str, ...]) -> Iterator[tuple[str, ...]]:
    """Register paper tasks on the tiny KITTI fixture (condition from the id), yield, unregister."""
    for task_id in ids:
        tasks.register(task_id, source="kitti", sequence="00", condition=task_id.split("-")[1],
                       step=1, map_config=MapConfig(size=32), n_seeds=1)
    yield ids
    for task_id in ids:
        tasks.unregister(task_id)


@pytest.fixture
def tiny_tasks(kitti_root: Path, safl_home: Path) -> Iterator[tuple[str, ...]]:
    yield from register_tiny(TASKS)


def options(kitti_root: Path, results: Path, **kw: object) -> runner.RunOptions:
    return runner.RunOptions(results_dir=results, kitti_root=str(kitti_root), progress=False,
                             timing_frames=3, timing_repeats=2, **kw)  # type: ignore[arg-type]


def test_cell_writes_a_complete_record_then_reuses_it(tiny_tasks, kitti_root, tmp_path):
    sad = make_method("sad")
    first = runner.run_cell(sad, tiny_tasks[0], options(kitti_root, tmp_path))
    assert first.status == "computed" and first.path.is_file()
    record = load_record(first.path)
    assert record.task.id == tiny_tasks[0] and record.task.condition == "T1R1"
    assert set(record.results) == {"sequence", "single_frame"}
    assert record.results["sequence"].metrics.n_queries == 12
    assert record.matcher["sequence"]["ds"] == 10 and record.matcher["single_frame"]["ds"] == 0
    assert record.timings.describe_ms_per_frame > 0
    assert record.method.params["params"] == sad.get_params()
    again = runner.run_cell(sad, tiny_tasks[0], options(kitti_root, tmp_path))
    assert again.status == "reused"
    assert again.record is not None and again.record.created == record.created


def test_corrupt_or_stale_records_are_recomputed(tiny_tasks, kitti_root, tmp_path):
    sad = make_method("sad")
    path = runner.run_cell(sad, tiny_tasks[0], options(kitti_root, tmp_path)).path
    path.write_text(path.read_text()[:100])
    said: list[str] = []
    out = runner.run_cell(sad, tiny_tasks[0], options(kitti_root, tmp_path), log=said.append)
    assert out.status == "computed" and str(path) in said[0]
    load_record(path)  # whole again
    other = make_method("sad", **{next(iter(sad.get_params())): 4}) if sad.get_params() else None
    if other is not None:
        said.clear()
        out = runner.run_cell(other, tiny_tasks[0], options(kitti_root, tmp_path), log=said.append)
        assert out.status == "computed" and "method settings differ" in said[0]
    forced = runner.run_cell(sad, tiny_tasks[0], options(kitti_root, tmp_path, force=True))
    assert forced.status == "computed"


def test_interrupted_run_resumes(tiny_tasks, kitti_root, tmp_path, monkeypatch):
    sad = make_method("sad")
    real = runner.evaluate_method
    calls = {"n": 0}

    def interrupt_second(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(runner, "evaluate_method", interrupt_second)
    with pytest.raises(KeyboardInterrupt):
        runner.run_cells(sad, tiny_tasks, options(kitti_root, tmp_path))
    done = list(tmp_path.rglob("*.json"))
    assert len(done) == 1 and not list(tmp_path.rglob("*.tmp*"))
    monkeypatch.setattr(runner, "evaluate_method", real)
    outcomes = runner.run_cells(sad, tiny_tasks, options(kitti_root, tmp_path))
    assert [o.status for o in outcomes] == ["reused", "computed"]


def test_seed_changes_queries_but_keeps_the_task_fingerprint(tiny_tasks, kitti_root, tmp_path):
    sad = make_method("sad")
    a = runner.run_cell(sad, tiny_tasks[1], options(kitti_root, tmp_path))
    b = runner.run_cell(sad, tiny_tasks[1], options(kitti_root, tmp_path, seed=7))
    assert a.path != b.path and b.record is not None and a.record is not None
    assert b.record.seed == 7 and a.record.seed == 0
    assert a.record.task.spec_fingerprint == b.record.task.spec_fingerprint


def test_cli_run_prints_the_table(tiny_tasks, kitti_root, tmp_path, capsys):
    rc = main(["run", "--method", "sad", "--task", tiny_tasks[0], "--kitti-root", str(kitti_root),
               "--results", str(tmp_path), "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "R@100%P" in out and tiny_tasks[0] in out and "computed" in out
    record = json.loads(next(tmp_path.rglob("seed-0.json")).read_text())
    assert record["method"]["name"] == "sad"
    # the default preset: Table I, the window from the database's self-difference dip
    assert record["matcher"]["sequence"]["enhance_rule"] == "dip"
    assert record["matcher"]["enhancement"]["window"] >= 2


def test_cli_run_matcher_settings_are_used_and_recorded(tiny_tasks, kitti_root, tmp_path, capsys,
                                                         monkeypatch):
    rc = main(["run", "--method", "sad", "--task", tiny_tasks[0], "--kitti-root", str(kitti_root),
               "--results", str(tmp_path), "--quiet", "--matcher", "enhance_window=0", "--matcher", "ds=3",
               "--score", "ratio"])
    assert rc == 0
    record = json.loads(next(tmp_path.rglob("seed-0.json")).read_text())
    seq = record["matcher"]["sequence"]
    assert (seq["enhance_window"], seq["ds"], seq["score"]) == (0, 3, "ratio")
    assert record["matcher"]["single_frame"]["score"] == "ratio"
    # a bad setting is named before the missing data folder is (no --kitti-root, no env)
    monkeypatch.delenv("SAFL_KITTI_ROOT", raising=False)
    assert main(["run", "--method", "sad", "--task", tiny_tasks[0], "--matcher", "speed=2"]) == 2
    assert "--matcher: unknown setting(s) ['speed']" in capsys.readouterr().err


def test_cli_run_bad_input_is_one_line(tiny_tasks, tmp_path, capsys):
    assert main(["run", "--method", "nope", "--results", str(tmp_path)]) == 2
    assert main(["run", "--method", "sad", "--task", "SAFL/Synth00-T3R1-v4"]) == 2
    assert main(["run", "--method", "sad", "--param", "oops"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("safl-bench: error:") for line in err)


def test_resolve_tasks_expands_suites():
    paper = runner.resolve_tasks([])
    assert len(paper) == 12 and all(t.startswith("SAFL/Synth00-") for t in paper)
    kitti = runner.resolve_tasks(["paper"], source="kitti")
    assert all(t.startswith("SAFL/KITTI00-") for t in kitti)
    mixed = runner.resolve_tasks(["SAFL/Synth00-T1R1-v6", "paper"])
    assert mixed[0] == "SAFL/Synth00-T1R1-v6" and len(mixed) == 12
    assert all(t.endswith("-v6") for t in paper)


def test_the_views_of_all_cells_are_rendered_in_one_pass(tiny_tasks, kitti_root, tmp_path, monkeypatch):
    """Cells on one sequence share one pass over the scans for all their conditions (the clean
    database and every query condition), not one pass each."""
    from safl_bench import mapbuild

    passes: list[list[str]] = []
    real = mapbuild.build_views

    def counted(seq, config, frames, offsets, kinds, progress=True):  # type: ignore[no-untyped-def]
        passes.append(sorted(offsets))
        return real(seq, config, frames, offsets, kinds, progress=progress)

    monkeypatch.setattr(mapbuild, "build_views", counted)
    out = runner.run_cells(make_method("sad"), tiny_tasks, options(kitti_root, tmp_path))
    assert [o.status for o in out] == ["computed", "computed"]
    assert passes == [["T0R0", "T1R1", "T5R1"]]


@pytest.mark.parametrize("command", [["run", "--method", "sad"], ["data", "prepare"], ["train", "--method", "bigan"]])
def test_a_negative_seed_is_refused_by_name(command, capsys):
    with pytest.raises(SystemExit) as exit_:
        main([*command, "--seed", "-1"])
    assert exit_.value.code == 2 and "a seed is an integer >= 0, got -1" in capsys.readouterr().err


def test_a_sequence_whose_views_cannot_be_rendered_fails_only_its_cells(kitti_copy, safl_home, tmp_path, capsys):
    """Views are rendered for all cells first; a broken scan in one sequence fails that
    sequence's cells, by file name, and the other sequence's cells complete."""
    write_kitti(kitti_copy, "01", n=12, seed=1)
    (kitti_copy / "sequences" / "01" / "velodyne" / "000005.bin").write_bytes(b"\0" * 10)
    ids = ("Test/TinyBroken00-T1R1-v0", "Test/TinyBroken01-T1R1-v0")
    for task_id, sequence in zip(ids, ("00", "01"), strict=True):
        tasks.register(task_id, source="kitti", sequence=sequence, condition="T1R1", step=1, n_seeds=1,
                       map_config=MapConfig(size=32))
    try:
        out = runner.run_cells(make_method("sad"), ids, options(kitti_copy, tmp_path))
    finally:
        for task_id in ids:
            tasks.unregister(task_id)
    assert [o.status for o in out] == ["computed", "failed"]
    assert "000005.bin" in out[1].message and not out[1].path.exists()


def test_summary_names_the_preset_and_explains_zeros_of_mostly_correct_cells(tmp_path):
    from dataclasses import replace

    from record_factory import make_record

    from safl_bench import matcher_presets

    paper = matcher_presets.get("paper").config.to_dict()
    zero = replace(make_record("sad", recall=0.0, recall_at_1=0.9, source_kind="bev",
                               source_label="KITTI top-view images"), matcher=paper)
    fine = replace(make_record("sad", condition="T5R1", recall=0.5, recall_at_1=0.9), matcher=paper)
    outcomes = [runner.CellOutcome(r.task.id, 0, "computed", tmp_path, r, method="sad") for r in (zero, fine)]
    lines = runner.summary_table(outcomes).splitlines()
    assert lines[0].split()[:7] == ["task", "seeds", "matcher", "R@100%P", "F1max", "R@1", "AUC"]
    assert lines[2].split()[:3] == [zero.task.id, "0", "paper"]
    assert lines[-1].startswith("note: recall at 100 % precision is 0.0 in 1 record(s) whose matches")
    assert f"safl-bench explain --method sad --task {zero.task.id} --bev-root DIR" in lines[-1]
    assert runner.zeros_note(outcomes[1:]) == ""


def test_a_method_reads_views_in_its_own_encoding(tiny_tasks, kitti_root, tmp_path):
    from safl_bench.method import Method, as_topview

    class DensityShape(Method):
        name = "density_shape"
        version = "1"
        view_encoding = "bev-density"

        def describe(self, maps):  # type: ignore[no-untyped-def]
            arr = as_topview(maps)
            assert arr.shape[1:] == (151, 151)  # BEVPlace's images, not the 64x64 occupancy maps
            return arr.reshape(len(arr), -1)[:, ::97].astype(np.float32)

    out = runner.run_cell(DensityShape(), tiny_tasks[0], options(kitti_root, tmp_path))
    assert out.status == "computed", out.message
    spec = out.record.task.spec
    assert spec["views_map_config"]["encoding"] == "bev-density"
    assert out.record.task.spec_fingerprint == tasks.spec(tiny_tasks[0]).fingerprint  # same leaderboard cell


def test_a_point_cloud_method_runs_a_cell(tiny_tasks, kitti_root, tmp_path):
    out = runner.run_cell(make_method("scan_context"), tiny_tasks[0], options(kitti_root, tmp_path))
    assert out.status == "computed" and "method_input" not in out.record.task.spec


def test_a_record_of_an_older_metrics_version_is_rescored_or_recomputed(tiny_tasks, kitti_root,
                                                                       tmp_path):
    sad = make_method("sad")
    first = runner.run_cell(sad, tiny_tasks[0], options(kitti_root, tmp_path))
    data = json.loads(first.path.read_text())
    good = data["results"]["sequence"]["metrics"]["f1_max"]
    # version 1 in name only, with its per-query outcomes: rescored from them, not recomputed
    data["metrics_version"] = 1
    data["results"]["sequence"]["metrics"]["f1_max"] = 0.0
    first.path.write_text(json.dumps(data))
    again = runner.run_cell(sad, tiny_tasks[0], options(kitti_root, tmp_path))
    assert again.status == "rescored" and again.record is not None
    assert again.record.metrics_version == METRICS_VERSION
    assert again.record.results["sequence"].metrics.f1_max == pytest.approx(good)
    assert again.record.created == json.loads(first.path.read_text())["created"]
    # a real version-1 record holds no outcomes: recomputed, keeping the run's timings
    for mode in data["results"].values():
        del mode["queries"]
    first.path.write_text(json.dumps(data))
    said: list[str] = []
    redone = runner.run_cell(sad, tiny_tasks[0], options(kitti_root, tmp_path), log=said.append)
    assert redone.status == "computed" and "metrics version 1" in said[0]
    assert redone.record is not None and redone.record.metrics_version == METRICS_VERSION
    assert redone.record.timings.describe_ms_per_frame == data["timings"]["describe_ms_per_frame"]
    assert "timed by the run of" in redone.record.timings.how_run
    assert redone.record.results["sequence"].metrics.f1_max == pytest.approx(good)


def test_a_task_whose_ground_truth_has_no_positive_is_named(kitti_root, safl_home, tmp_path):
    # a 30 s window on 12 frames at 10 Hz: no query has a candidate, so none has a true place
    task_id = "Test/TinyRun-Revisit-v0"
    tasks.register(task_id, source="kitti", sequence="00", protocol="revisit", step=1,
                   tp_radius_m=3.0, fp_radius_m=20.0, window_s=30.0, map_config=MapConfig(size=32))
    try:
        out = runner.run_grid([make_method("sad")], [task_id], options(kitti_root, tmp_path),
                              log=lambda message: None)
    finally:
        tasks.unregister(task_id)
    assert out[0].status == "failed"
    assert out[0].message.startswith(f"task {task_id} (seed 0): no query has a true place")
    assert "\n" not in out[0].message


def test_candidates_beyond_the_database_stop_the_run_before_any_view(tiny_tasks, kitti_root,
                                                                     tmp_path, monkeypatch):
    import dataclasses

    from safl_bench.errors import ConfigError
    from safl_bench.matching.presets import default_config

    def no_views(*a: object, **k: object) -> None:
        raise AssertionError("views were rendered before the option was checked")

    monkeypatch.setattr(runner, "prepare_tasks", no_views)
    evaluation = dataclasses.replace(default_config(), candidates=500, distance="euclidean")
    with pytest.raises(ConfigError, match=r"task Test/TinyRun-T1R1-v0: candidates=500 is more "
                                          r"than the database's \d+ frames"):
        runner.run_grid([make_method("sad")], list(tiny_tasks),
                        options(kitti_root, tmp_path, evaluation=evaluation))
    assert not list(tmp_path.rglob("*.json"))
