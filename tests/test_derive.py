"""Records of a new task version derived from the version it replaced equal a full recompute
(`safl_bench.results.derive`), through the runner, `records migrate` and the function itself."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path

import pytest

from safl_bench import runner, tasks
from safl_bench.cli import main
from safl_bench.matching.presets import configure
from safl_bench.method_registry import make_method
from safl_bench.records import ResultRecord, load_record, record_path, write_record
from safl_bench.results.derive import NotDerivableError, derive_record
from safl_bench.tasks.builtin import predecessor, successor

OLD, NEW = "Test/Derive-T5R1-v0", "Test/Derive-T5R1-v1"


@pytest.fixture
def pair(bev_root: Path, safl_home: Path) -> Iterator[tuple[str, str]]:
    """A paper task on the 40-frame image fixture that scores every query, and its successor
    whose first 10 queries are context."""
    for task_id, context in ((OLD, 0), (NEW, 10)):
        tasks.register(task_id, source="bev", sequence="00", condition="T5R1", step=1, n_seeds=1,
                       map_config=None, context_queries=context)
    yield OLD, NEW
    for task_id in (OLD, NEW):
        tasks.unregister(task_id)


def options(bev_root: Path, results: Path, preset: str = "paper") -> runner.RunOptions:
    return runner.RunOptions(results_dir=results, bev_root=str(bev_root), progress=False,
                             timing_frames=2, timing_repeats=1,
                             evaluation=configure(preset))


def same_scores(a: ResultRecord, b: ResultRecord) -> None:
    """Everything a record says about the measures and the scored queries is equal."""
    assert a.task == b.task
    for mode in ("sequence", "single_frame"):
        assert a.results[mode] == b.results[mode], mode
    assert (a.method, a.seed, a.matcher, a.metrics_version) == (b.method, b.seed, b.matcher,
                                                                b.metrics_version)


@pytest.mark.parametrize("preset", ["paper", "authors"])
def test_a_derived_record_equals_a_recompute(pair, bev_root, tmp_path, preset):
    old_id, new_id = pair
    assert successor(old_id) == new_id and predecessor(new_id) == old_id
    sad = make_method("sad")
    old = runner.run_cell(sad, old_id, options(bev_root, tmp_path / "old", preset))
    computed = runner.run_cell(sad, new_id, options(bev_root, tmp_path / "new", preset))
    assert old.record is not None and computed.status == "computed" and computed.record is not None
    derived = derive_record(old.record, tasks.registry[new_id])
    same_scores(derived, computed.record)
    # what the new version leaves out: the first 10 queries (the authors' trim of 5 included)
    trim = old.record.matcher["evaluation"]["trim_queries"]
    n_old = old.record.results["sequence"].metrics.n_queries
    assert derived.results["sequence"].metrics.n_queries == n_old - (10 - trim)
    assert derived.derived_from is not None and derived.derived_from.task == old_id
    assert derived.derived_from.created == old.record.created
    assert derived.timings == old.record.timings
    # the runner derives a missing cell from the old record in the same folder
    again = runner.run_cell(sad, new_id, options(bev_root, tmp_path / "old", preset))
    assert again.status == "derived" and again.record is not None
    same_scores(load_record(again.path), computed.record)
    assert runner.run_cell(sad, new_id, options(bev_root, tmp_path / "old", preset)).status == "reused"


def test_records_migrate_moves_a_folder(pair, bev_root, tmp_path, capsys):
    old_id, new_id = pair
    sad = make_method("sad")
    old = runner.run_cell(sad, old_id, options(bev_root, tmp_path))
    assert main(["records", "migrate", str(tmp_path), "--remove"]) == 0
    assert "1 records derived, 1 old records removed, 0 kept" in capsys.readouterr().out
    assert not old.path.exists()
    moved = load_record(record_path(tmp_path, "sad", sad.version, new_id, 0))
    assert moved.task.id == new_id and moved.derived_from is not None


def test_what_cannot_be_derived_is_refused(pair, bev_root, tmp_path):
    old_id, new_id = pair
    old = runner.run_cell(make_method("sad"), old_id, options(bev_root, tmp_path)).record
    assert old is not None
    with pytest.raises(NotDerivableError, match="does not replace"):
        derive_record(old, tasks.registry[old_id])
    no_outcomes = dataclasses.replace(old, results={
        m: dataclasses.replace(r, queries=None) for m, r in old.results.items()})
    with pytest.raises(NotDerivableError, match="no per-query outcomes"):
        derive_record(no_outcomes, tasks.registry[new_id])
    other = dataclasses.replace(old, task=dataclasses.replace(old.task, spec_fingerprint="0" * 16))
    with pytest.raises(NotDerivableError, match="another definition"):
        derive_record(other, tasks.registry[new_id])
    write_record(tmp_path / "bad", no_outcomes)  # the runner computes the cell instead
    said: list[str] = []
    out = runner.run_cell(make_method("sad"), new_id, options(bev_root, tmp_path / "bad"),
                          log=said.append)
    assert out.status == "computed" and any("cannot be derived from" in s for s in said)


def test_the_leaderboard_names_old_versions_and_tables_them_apart(pair, bev_root, tmp_path, capsys):
    old_id, new_id = pair
    sad = make_method("sad")
    runner.run_cell(sad, old_id, options(bev_root, tmp_path / "records"))
    runner.run_cell(sad, new_id, options(bev_root, tmp_path / "records"))  # both in one folder
    assert main(["leaderboard", "--out", str(tmp_path), "--no-figures", "--no-site"]) == 0
    err = capsys.readouterr().err
    notes = [line for line in err.splitlines() if "replaced" in line]
    assert len(notes) == 1 and old_id in notes[0] and "records migrate" in notes[0]
    tables = {p.name for p in (tmp_path / "tables").rglob("*.md")}
    assert any("-v0-" in t for t in tables) and any("-v1-" in t for t in tables)
