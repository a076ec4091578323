"""Seeds are part of a cell: tasks declare how many noise seeds they average, `run` runs them all
by default, `--seeds N` / `--seed S` override, and the run table shows means with intervals."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from safl_bench import runner, tasks
from safl_bench.cli import main
from safl_bench.errors import ConfigError
from safl_bench.mapconfig import MapConfig
from safl_bench.method_registry import make_method
from safl_bench.tasks import spec
from safl_bench.tasks.spec import DEFAULT_NOISY_SEEDS

NOISY, FIXED = "Test/SeedsNoisy-T1R1-v0", "Test/SeedsFixed-Revisit-v0"


@pytest.fixture
def seed_tasks(kitti_root: Path, safl_home: Path) -> Iterator[None]:
    tasks.register(NOISY, source="kitti", sequence="00", condition="T1R1", step=1,
                   map_config=MapConfig(size=32), n_seeds=3)
    tasks.register(FIXED, source="kitti", sequence="00", protocol="revisit", step=1,
                   window_s=0.0, tp_radius_m=3.0, fp_radius_m=20.0, map_config=MapConfig(size=32))
    yield
    tasks.unregister(NOISY)
    tasks.unregister(FIXED)


def _options(kitti_root: Path, results: Path) -> runner.RunOptions:
    return runner.RunOptions(results_dir=results, kitti_root=str(kitti_root), progress=False,
                             timing_frames=2, timing_repeats=1)


def test_noisy_tasks_declare_five_seeds_and_fixed_ones_one() -> None:
    assert DEFAULT_NOISY_SEEDS == 5
    assert spec("SAFL/Synth00-T1R1-v6").seeds == (0, 1, 2, 3, 4)
    assert spec("SAFL/BEVKITTI00-T20R2-v1").seeds == (0, 1, 2, 3, 4)
    for fixed in ("SAFL/Synth00-Revisit-v6", "SAFL/BEVKITTI00-BEVPlace-v1", "SAFL/Synth00-T0R0-v6"):
        assert spec(fixed).seeds == (0,), fixed


def test_a_task_can_declare_its_seed_count_and_a_bad_one_is_refused() -> None:
    from safl_bench.tasks.spec import TaskSpec

    task = TaskSpec("Test/Own-T1R1-v0", source="synth", sequence="00", condition="T1R1", seed=7,
                    n_seeds=2)
    assert task.seeds == (7, 8)
    # the count says how many draws a cell takes, not what the task is: same fingerprint
    assert task.fingerprint == TaskSpec("Test/Own-T1R1-v0", source="synth", sequence="00",
                                        condition="T1R1", seed=7).fingerprint
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ConfigError, match="n_seeds must be an integer >= 1"):
            TaskSpec("Test/Own-T1R1-v0", source="synth", sequence="00", condition="T1R1", n_seeds=bad)


def test_cell_seeds_follow_the_task_unless_overridden() -> None:
    noisy, fixed = spec("SAFL/Synth00-T5R1-v6"), spec("SAFL/Synth00-Revisit-v6")
    assert runner.cell_seeds(noisy) == (0, 1, 2, 3, 4)
    assert runner.cell_seeds(noisy, n_seeds=2) == (0, 1)
    assert runner.cell_seeds(fixed, n_seeds=3) == (0,)  # nothing random: one seed is the cell
    assert runner.cell_seeds(fixed, seeds=[4, 2]) == (4, 2)  # asked for by name: run as asked


def test_a_method_that_cannot_be_seeded_runs_a_fixed_task_several_times() -> None:
    """MapClosures' RANSAC cannot be seeded: on a task where nothing is random its cell runs
    REPEATS times, as seeds the records and tables read as runs of one cell (`is_repeat`)."""
    import dataclasses

    from record_factory import make_record

    from safl_bench.results.records import is_repeat

    class Unseeded:
        deterministic = False

    noisy, fixed = spec("SAFL/Synth00-T5R1-v6"), spec("SAFL/Synth00-Revisit-v6")
    assert runner.cell_seeds(fixed, method=Unseeded()) == tuple(range(runner.REPEATS)) == (0, 1, 2)  # type: ignore[arg-type]
    assert runner.cell_seeds(fixed, n_seeds=5, method=Unseeded()) == (0, 1, 2, 3, 4)  # type: ignore[arg-type]
    assert runner.cell_seeds(noisy, method=Unseeded()) == (0, 1, 2, 3, 4)  # type: ignore[arg-type]  # its seeds already
    assert runner.cell_seeds(fixed, method=make_method("sad", size=16)) == (0,)
    revisit = make_record("mc", protocol="revisit", sequence="00", deterministic=False)
    assert not is_repeat(revisit) and is_repeat(dataclasses.replace(revisit, seed=2))
    assert not is_repeat(make_record(seed=3, condition="T1R1", deterministic=False))  # a noise seed
    assert is_repeat(make_record(seed=1, condition="T0R0", deterministic=False))
    # a seedable method's other seeds on a fixed task stay seeds
    assert not is_repeat(make_record("sad", protocol="revisit", seed=1))
    # the record says which kind of method made it
    sad = make_method("sad", size=16)
    assert runner.method_info(sad).deterministic
    sad.deterministic = False  # type: ignore[attr-defined]
    assert not runner.method_info(sad).deterministic


def test_tables_read_repeated_runs_as_one_cell() -> None:
    import dataclasses

    from record_factory import make_record

    from safl_bench.leaderboard.grouping import table_key
    from safl_bench.leaderboard.tables import revisit_table

    runs = [dataclasses.replace(make_record("mc", protocol="revisit", f1=0.5 + 0.01 * k,
                                          deterministic=False), seed=k) for k in range(3)]
    other = make_record("a", protocol="revisit", f1=0.8)
    table = revisit_table(table_key(other), [*runs, other])
    assert table.seeds == frozenset({0})  # the table's seeds: the runs do not widen them
    notes = "\n".join(table.notes)
    assert "mc v1 sequence: seeds 0, 1, 2 are runs of one cell" in notes
    assert "over seed(s)" not in notes  # neither row is called a row over other seeds
    row = table.rows.index(("mc", "1", "sequence"))
    (col,) = [j for j, c in enumerate(table.columns) if c.endswith("F1max")]
    cell = table.cells[row][col]
    assert cell is not None and cell.mean is not None and abs(cell.mean - 0.51) < 1e-9
    assert cell.seeds == table.seeds and "(seed 0, 1, 2)" not in table.markdown()  # runs, not seeds


def test_run_runs_every_declared_seed_once_and_reuses_them(seed_tasks, kitti_root, tmp_path) -> None:
    sad = make_method("sad", size=16)
    first = runner.run_grid([sad], [NOISY, FIXED], _options(kitti_root, tmp_path))
    assert [(o.task_id, o.seed, o.status) for o in first] == [
        (NOISY, 0, "computed"), (FIXED, 0, "computed"), (NOISY, 1, "computed"), (NOISY, 2, "computed")]
    assert sorted(p.name for p in (tmp_path / "sad@1" / "Test__SeedsNoisy-T1R1-v0").iterdir()) == [
        "seed-0.json", "seed-1.json", "seed-2.json"]
    # seeds draw different noise: their queries' confidences differ
    confidences = {tuple(o.record.results["single_frame"].queries.confidence)  # type: ignore[union-attr]
                   for o in first if o.task_id == NOISY and o.record is not None}
    assert len(confidences) == 3
    again = runner.run_grid([sad], [NOISY, FIXED], _options(kitti_root, tmp_path), n_seeds=2)
    assert [(o.task_id, o.seed, o.status) for o in again] == [
        (NOISY, 0, "reused"), (FIXED, 0, "reused"), (NOISY, 1, "reused")]
    table = runner.summary_table(first).splitlines()
    assert table[0].split()[:3] == ["task", "seeds", "matcher"]
    noisy_row = next(line for line in table if line.startswith(NOISY))
    assert noisy_row.split()[1] == "0-2" and "[" in noisy_row and "computed 3" in noisy_row
    assert any("95 % interval over seeds and queries" in line for line in table)
    # the seeds carry the cell's one timing: shown as one, not as a bracket of zero width
    ms = {o.record.timings.describe_ms_per_frame for o in first  # type: ignore[union-attr]
          if o.task_id == NOISY}
    assert len(ms) == 1 and f"{ms.pop():.2f} (1 timing)" in noisy_row


def test_seeds_share_the_cells_timing_and_database_and_records_stay_the_same(
        seed_tasks, kitti_root, tmp_path, monkeypatch) -> None:
    from safl_bench import evaluation

    sizes: list[int] = []
    plain = evaluation.describe

    def counted(method, views, *rest):  # type: ignore[no-untyped-def]
        sizes.append(len(views))
        return plain(method, views, *rest)

    monkeypatch.setattr(evaluation, "describe", counted)
    from safl_bench import sources

    opened: list[str] = []
    open_source = sources.open_source

    def counted_open(task_spec, **kwargs):  # type: ignore[no-untyped-def]
        opened.append(task_spec.id)
        return open_source(task_spec, **kwargs)

    monkeypatch.setattr(sources, "open_source", counted_open)
    sad = make_method("sad", size=16)
    alone = runner.run_grid([sad], [NOISY], runner.RunOptions(
        results_dir=tmp_path / "alone", kitti_root=str(kitti_root), progress=False,
        timing_frames=2, timing_repeats=1, share_seeds=False))
    described_alone, sizes[:] = len(sizes), []
    opened_alone, opened[:] = len(opened), []
    shared = runner.run_grid([sad], [NOISY], _options(kitti_root, tmp_path / "shared"))
    assert described_alone == 6 and len(sizes) == 4  # one database for the three seeds' queries
    assert opened_alone == 3 and len(opened) == 1  # the data opened once for the three seeds
    assert [o.seed for o in shared] == [0, 1, 2]
    first = shared[0].record
    assert first is not None and "measured at seed" not in first.timings.how_run
    for a, b in zip(alone, shared, strict=True):
        assert a.record is not None and b.record is not None
        left, right = a.record.to_json(), b.record.to_json()
        for varying in ("timings", "created", "environment"):
            left.pop(varying), right.pop(varying)
        assert left == right  # the same matches, outcomes and metrics
        assert "measured at seed" not in a.record.timings.how_run  # alone: each seed timed
        if b.seed > 0:
            t = b.record.timings
            assert t.how_run.endswith("the cell's timing (describe_ms_per_frame, peak_memory_mb), "
                                      "measured at seed 0")
            assert (t.describe_ms_per_frame, t.peak_memory_mb) == (
                first.timings.describe_ms_per_frame, first.timings.peak_memory_mb)
    # a later run of one more seed times it anew: what a run carries is its own measurement
    more = runner.run_grid([sad], [NOISY], _options(kitti_root, tmp_path / "shared"), seeds=[3])
    assert more[0].record is not None and "measured at seed" not in more[0].record.timings.how_run


@pytest.mark.parametrize(("args", "message"), [
    (["--seeds", "0"], "a number of seeds is an integer >= 1, got 0"),
    (["--seeds", "two"], "a number of seeds is an integer >= 1, got 'two'"),
    (["--seed", "-1"], "a seed is an integer >= 0, got -1"),
    (["--seed", "3", "--seed", "1", "--seed", "3"], "--seed 3 given more than once"),
    (["--seed", "1", "--seeds", "2"], "not allowed with argument"),
])
def test_bad_seeds_are_one_line_and_exit_2(args, message, capsys) -> None:
    try:
        code = main(["run", "--method", "sad", *args])
    except SystemExit as exc:  # argparse's refusals
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and message in err
    assert len(err.strip().splitlines()) == 1, err


def test_repeated_runs_are_ranked_run_by_run_against_one_run() -> None:
    import dataclasses

    from record_factory import make_record

    from safl_bench.leaderboard.intervals import _runs_paired

    runs = tuple(dataclasses.replace(make_record("mc", protocol="revisit", deterministic=False), seed=k)
                 for k in range(3))
    one = (make_record("a", protocol="revisit"),)
    paired = _runs_paired(runs, one)
    assert [r.seed for r in paired] == [0, 1, 2] and all(r.method.name == "a" for r in paired)
    assert _runs_paired(one, runs) == runs  # the runs stay as they are
    noisy = tuple(make_record("b", seed=k) for k in range(3))  # noise seeds, not runs
    assert _runs_paired(noisy, one) == one
