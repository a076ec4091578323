"""The loop-closure stage (`safl_bench.slam`, `safl-bench slam`): pose graphs built here on small
trajectories, and one revisit cell run from a record made here (never real KITTI)."""

from __future__ import annotations

import itertools
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from conftest import write_bev

pytest.importorskip("gtsam")
pytest.importorskip("evo")

from safl_bench import tasks
from safl_bench.cli import main as cli_main
from safl_bench.errors import ConfigError, DataError
from safl_bench.results.records import dumps_record, load_record
from safl_bench.slam import cell as slam_cell
from safl_bench.slam.backend import solve, trajectory_errors
from safl_bench.slam.model import (
    DRIFT_LEVELS,
    between,
    closure_measurements,
    compose,
    integrate,
    simulate_odometry,
    wrap,
)


def loop_poses(laps: int = 2, step: float = 4.0) -> np.ndarray:
    """A 400 m x 250 m block driven `laps` times, a pose every `step` metres, heading along."""
    corners = np.array([[0, 0], [400, 0], [400, 250], [0, 250], [0, 0]], float)
    points = []
    for a, b in itertools.pairwise(corners):
        n = round(float(np.linalg.norm(b - a)) / step)
        points += [a + (b - a) * k / n for k in range(n)]
    xy = np.array(points * laps)
    heading = np.arctan2(*(np.roll(xy, -1, axis=0) - xy)[:, ::-1].T)
    return np.column_stack([xy, heading])


def revisit_closures(poses: np.ndarray, every: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """(query, match): the second lap's poses matched to the same place on the first."""
    lap = len(poses) // 2
    query = np.arange(lap, len(poses), every)
    return query, query - lap


def test_se2_helpers_invert_each_other() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    np.testing.assert_allclose(compose(a, between(a, b))[:, :2], b[:, :2], atol=1e-12)
    poses = loop_poses(1)
    again = integrate(poses[0], between(poses[:-1], poses[1:]))
    np.testing.assert_allclose(again[:, :2], poses[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrap(again[:, 2] - poses[:, 2]), 0.0, atol=1e-9)


def test_drift_levels_are_cited_and_odometry_is_seeded() -> None:
    assert list(DRIFT_LEVELS) == ["low", "mid", "high"]
    assert all(level.source for level in DRIFT_LEVELS.values())
    poses = loop_poses()
    a, b = (simulate_odometry(poses, DRIFT_LEVELS["mid"], 3) for _ in range(2))
    np.testing.assert_array_equal(a.trajectory, b.trajectory)
    other = simulate_odometry(poses, DRIFT_LEVELS["mid"], 4)
    assert not np.array_equal(a.trajectory, other.trajectory)
    errors = [trajectory_errors(poses, simulate_odometry(poses, DRIFT_LEVELS[name], 3).trajectory,
                                100.0).ate_m for name in ("low", "high")]
    assert 0 < errors[0] < errors[1]


def test_true_closures_pull_the_trajectory_back_to_the_truth() -> None:
    poses = loop_poses()
    odometry = simulate_odometry(poses, DRIFT_LEVELS["high"], 0)
    query, match = revisit_closures(poses)
    closures = closure_measurements(poses, query, match, np.ones(len(query), bool),
                                    np.ones(len(query)), seed=0)
    alone = trajectory_errors(poses, odometry.trajectory, 100.0)
    for backend in ("least-squares", "cauchy", "gnc-tls"):
        solution = solve(poses[0], odometry, closures, backend)
        assert solution.converged, solution.note
        assert solution.trajectory is not None
        errors = trajectory_errors(poses, solution.trajectory, 100.0)
        # the 3 % scale error stays; a Cauchy kernel started from the drifted odometry discounts
        # the true closures that are far from it, so it corrects less than the other two
        assert errors.ate_m < (0.95 if backend == "cauchy" else 0.7) * alone.ate_m, backend
    assert solution.kept is not None and solution.kept.mean() > 0.9  # GNC keeps most true ones


def test_a_false_closure_hurts_least_squares_more_than_gnc() -> None:
    poses = loop_poses()
    odometry = simulate_odometry(poses, DRIFT_LEVELS["mid"], 1)
    query, match = revisit_closures(poses)
    wrong_q, wrong_m = np.array([len(poses) - 40, len(poses) - 100]), np.array([60, 10])
    closures = closure_measurements(
        poses, np.r_[query, wrong_q], np.r_[match, wrong_m],
        np.r_[np.ones(len(query), bool), np.zeros(2, bool)], np.ones(len(query) + 2), seed=1)
    ate = {}
    for backend in ("least-squares", "gnc-tls"):
        solution = solve(poses[0], odometry, closures, backend)
        assert solution.converged and solution.trajectory is not None, solution.note
        ate[backend] = trajectory_errors(poses, solution.trajectory, 100.0).ate_m
    assert ate["least-squares"] > 2 * ate["gnc-tls"]
    assert solution.kept is not None and not solution.kept[-2:].any() and solution.kept[:-2].mean() > 0.9


def test_the_oracle_threshold_keeps_only_true_closures() -> None:
    confidence = np.array([5.0, 4.0, 3.0, 2.0, 1.0])
    assert slam_cell.oracle_threshold(confidence, np.array([1, 1, 0, 1, 1], bool)) == 4.0
    assert slam_cell.oracle_threshold(confidence, np.array([0, 1, 1, 1, 1], bool)) is None
    assert slam_cell.oracle_threshold(confidence, np.ones(5, bool)) == 1.0


# --------------------------------------------------------------------------------------------
# One revisit cell, from a record made here: the fixture folder's route drives 30 m out and back


TASK = "Test/SlamTiny-Revisit-v0"
OTHER = "Test/SlamTiny02-Revisit-v0"  # another sequence, to choose a threshold on


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, Path]]:
    """(top-view root, results folder) holding SAD's record of a tiny revisit task."""
    from safl_bench.methods.method import make_method
    from safl_bench.run import runner

    base = tmp_path_factory.mktemp("slam")
    root = write_bev(base / "bev", n=60)
    write_bev(root, name="02", n=60, seed=1)
    results = base / "results"
    for task_id, sequence in ((TASK, "00"), (OTHER, "02")):
        tasks.register(task_id, source="bev", sequence=sequence, protocol="revisit", step=1,
                       tp_radius_m=3.0, fp_radius_m=20.0, window_s=5.0)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SAFL_HOME", str(base / "home"))
        options = runner.RunOptions(results_dir=results, bev_root=str(root), progress=False,
                                    timing_frames=3, timing_repeats=1)
        for task_id in (TASK, OTHER):
            out = runner.run_cell(make_method("sad"), task_id, options, log=lambda message: None)
            assert out.status == "computed", out.message
        yield root, results
    tasks.unregister(TASK)
    tasks.unregister(OTHER)


def _run(capsys: pytest.CaptureFixture[str], root: Path, results: Path,
         *extra: str) -> tuple[int, str, str]:
    code = cli_main(["slam", "--method", "sad", "--task", TASK, "--bev-root", str(root),
                     "--results", str(results), "--rpe-delta", "10", *extra])
    out, err = capsys.readouterr()
    return code, out, err


def _record_file(results: Path) -> Path:
    (path,) = results.rglob("Test__SlamTiny-Revisit-v0/seed-0.json")
    return path


def test_the_record_holds_each_querys_match(cell: tuple[Path, Path]) -> None:
    record = load_record(_record_file(cell[1]))
    for mode in record.results.values():
        assert mode.queries is not None and mode.queries.match is not None
        o = mode.queries.outcomes()
        assert o.match is not None
        np.testing.assert_array_equal(o.match >= 0, np.isfinite(o.confidence))


def test_slam_runs_five_seeds_with_intervals_and_resumes(
        cell: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    root, results = cell
    code, out, err = _run(capsys, root, results)
    assert code == 0, err
    for word in ("odometry alone", "least-squares", "cauchy", "gnc-tls", "closures accepted", "oracle",
                 "SLAM seeds 0, 1, 2, 3, 4", "95 % interval"):
        assert word in out
    paths = sorted(results.rglob("slam-seed-0.s*.json"))
    assert [p.name.split(".")[1] for p in paths] == ["s0", "s1", "s2", "s3", "s4"]
    first = [json.loads(p.read_text()) for p in paths]
    assert {r["kind"] for r in first} == {slam_cell.RESULT_KIND}
    assert [r["slam_seed"] for r in first] == [0, 1, 2, 3, 4] and {r["seed"] for r in first} == {0}
    assert [b["backend"] for b in first[0]["backends"]] == ["least-squares", "cauchy", "gnc-tls"]
    assert first[0]["closures_false"] == 0 and first[0]["n_poses"] == 60
    assert len({r["odometry_ate_m"] for r in first}) == 5  # a drift draw per seed
    # the interval printed is the bootstrap over the five seeds' values
    interval = slam_cell.seed_interval([r["odometry_ate_m"] for r in first])
    assert interval.format(decimals=2) in out and interval.low <= interval.mean <= interval.high
    # a re-run resumes: the files are read, not recomputed (same 'created')
    paths[2].unlink()
    assert _run(capsys, root, results)[0] == 0
    again = [json.loads(p.read_text()) for p in sorted(results.rglob("slam-seed-0.s*.json"))]
    assert [r["created"] for r in again][:2] == [r["created"] for r in first][:2]
    assert paths[2].is_file()  # the missing seed computed again
    for result in (first[2], again[2]):
        result.pop("created"), result.pop("seconds")
    assert again[2] == first[2]
    # other settings are other files
    assert _run(capsys, root, results, "--drift", "high", "--slam-seeds", "2")[0] == 0
    assert len(list(results.rglob("slam-seed-0.s*.json"))) == 7


def test_paired_differences_over_seeds_cancel_the_shared_drift() -> None:
    base = np.array([10.0, 14.0, 9.0, 12.0, 20.0])
    diff = slam_cell.paired_ate_difference(base + 1.0, base)
    assert diff.mean == pytest.approx(1.0) and diff.low == pytest.approx(1.0) and diff.excludes_zero()
    assert not slam_cell.seed_interval(base).excludes_zero() or slam_cell.seed_interval(base).low > 0
    assert slam_cell.seed_interval([1.0, float("nan")]).format() == "n/a"


def test_a_non_converged_back_end_is_reported_as_such() -> None:
    def result(seed: int, ate: float | None) -> slam_cell.SlamResult:
        backends = [slam_cell.BackendResult(n, ate is not None or n != "gnc-tls", "why",
                                            1.0 if n != "gnc-tls" else ate, None)
                    for n in ("least-squares", "cauchy", "gnc-tls")]
        return slam_cell.SlamResult(
            method="m@1", task="T", seed=0, settings={}, threshold=None, threshold_rule="r",
            drift={"level": "mid"}, n_poses=3, closures_true=0, closures_false=0, odometry_ate_m=2.0,
            odometry_rpe_m=None, backends=backends, seconds=0.0, record_created="", slam_seed=seed)
    text = slam_cell.summary_table([result(0, 1.0), result(1, None)])
    line = next(x for x in text.splitlines() if x.startswith("gnc-tls"))
    assert "n/a" in line and "did not converge on seed(s) 1" in line


def test_deployment_pairs_each_sequence_with_another() -> None:
    for task, other in slam_cell.DEPLOY_FROM.items():
        assert other != task and slam_cell.DEPLOY_FROM[other] == task
    assert slam_cell.deploy_source("SAFL/BEVKITTI00-Revisit-v0") == "SAFL/BEVKITTI02-Revisit-v0"
    assert slam_cell.deploy_source("SAFL/BEVKITTI00-Revisit-RotQueries-v0") == "SAFL/BEVKITTI02-Revisit-v0"
    with pytest.raises(ConfigError, match="--threshold-from"):
        slam_cell.deploy_source("Test/Nowhere-Revisit-v0")


def test_a_methods_own_relative_pose_is_the_closures_measurement(cell: tuple[Path, Path]) -> None:
    from safl_bench.tasks.task import Task

    root, results = cell
    path = _record_file(results)
    data = json.loads(path.read_text())
    queries = data["results"]["sequence"]["queries"]
    n = len(queries["match"])
    # the method says: the match sits 1 m ahead of the query, turned by 0.1 rad; none for query 0
    queries["relative_pose"] = [None] + [[1.0, 0.0, 0.1]] * (n - 1)
    record = load_record_text(dumps_record(data), path)
    from safl_bench.tasks.registry import runnable_spec

    task = Task.from_spec(runnable_spec(TASK), bev_root=str(root), progress=False)
    below = float(np.nanmin(np.where(np.array(queries["match"]) >= 0,
                                     record.results["sequence"].queries.outcomes().confidence, np.nan)))
    settings = slam_cell.SlamSettings(threshold=below, rpe_delta_m=10.0)
    own = slam_cell.run_slam(record, task, settings)
    accepted = own.closures_true + own.closures_false
    assert accepted > 1 and own.closures_estimated == accepted - (queries["match"][0] >= 0)
    plain = slam_cell.run_slam(load_record(path), task, settings)
    assert plain.closures_estimated == 0 and own.backends[0].ate_m != plain.backends[0].ate_m
    # the measurement is the estimate inverted: the query 1 m behind the match, turned back
    measured = closure_measurements(np.zeros((3, 3)), np.array([1, 2]), np.array([0, 0]),
                                    np.array([True, False]), np.ones(2), 0,
                                    np.array([[1.0, 0.0, 0.1], [np.nan] * 3]))
    assert measured.estimated is not None and measured.estimated.tolist() == [True, False]
    np.testing.assert_allclose(compose(np.array([1.0, 0.0, 0.1]), measured.measured[0]), 0, atol=1e-12)


def load_record_text(text: str, like: Path):  # type: ignore[no-untyped-def]
    """A record loaded from `text` (written beside `like`'s folder, in a temporary name)."""
    target = like.with_name("relpose-tmp.json")
    target.write_text(text)
    try:
        return load_record(target)
    finally:
        target.unlink()


def test_a_threshold_below_every_match_accepts_them_all(cell: tuple[Path, Path],
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    root, results = cell
    record = load_record(_record_file(results))
    queries = record.results["sequence"].queries
    assert queries is not None and queries.match is not None
    match, confidence = np.array(queries.match), queries.outcomes().confidence
    low = float(confidence[match >= 0].min())
    out = results / "all.json"
    code, _, err = _run(capsys, root, results, "--threshold", repr(low), "--out", str(out))
    assert code == 0, err
    data = json.loads(out.read_text())
    assert data["closures_true"] + data["closures_false"] == int((match >= 0).sum())
    assert data["threshold_rule"] == "given"


def test_a_threshold_chosen_on_another_sequence_is_deployed(
        cell: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    root, results = cell
    out = results / "deployed.json"
    code, text, err = _run(capsys, root, results, "--threshold-from", OTHER, "--out", str(out))
    assert code == 0, err
    data = json.loads(out.read_text())
    assert data["threshold_rule"].startswith(f"deployed: the lowest keeping 100 % precision on {OTHER}")
    other = load_record(next(results.rglob("Test__SlamTiny02-Revisit-v0/seed-0.json")))
    assert data["threshold"] == slam_cell.deployed_threshold(other)
    assert "deployed" in text
    err = _one_line_error(*_run(capsys, root, results, "--threshold-from", OTHER,
                                "--threshold", "1")[::2])
    assert "not both" in err


def test_a_curve_runs_from_no_closure_to_every_match(cell: tuple[Path, Path],
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    root, results = cell
    out = results / "curve.json"
    code, text, err = _run(capsys, root, results, "--curve", "4", "--out", str(out))
    assert code == 0, err
    curve = json.loads(out.read_text())["curve"]
    assert curve[0]["threshold"] is None and curve[0]["closures_true"] + curve[0]["closures_false"] == 0
    record = load_record(_record_file(results))
    queries = record.results["sequence"].queries
    assert queries is not None and queries.match is not None
    last = curve[-1]
    assert last["closures_true"] + last["closures_false"] == sum(m >= 0 for m in queries.match)
    accepted = [r["closures_true"] + r["closures_false"] for r in curve]
    assert accepted == sorted(accepted) and len(text.splitlines()) == 2 + len(curve) + 1
    err = _one_line_error(*_run(capsys, root, results, "--curve", "4", "--threshold", "1")[::2])
    assert "--curve takes its own thresholds" in err


def _one_line_error(code: int, err: str) -> str:
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    return err


def test_bad_input_is_one_line(cell: tuple[Path, Path], capsys: pytest.CaptureFixture[str],
                               tmp_path: Path) -> None:
    root, results = cell
    err = _one_line_error(*_run(capsys, root, results, "--threshold", "1e9")[::2])
    assert "outside the confidences" in err
    # a record made before the matches were stored, and one without per-query outcomes
    old = tmp_path / "old"
    path = _record_file(results)
    target = old / path.relative_to(results)
    target.parent.mkdir(parents=True)
    data = json.loads(path.read_text())
    for mode in data["results"].values():
        del mode["queries"]["match"]
    target.write_text(dumps_record(data))
    err = _one_line_error(*_run(capsys, root, old)[::2])
    assert "predates per-query matches" in err and "--force" in err
    for mode in data["results"].values():
        mode["queries"] = None
    target.write_text(dumps_record(data))
    err = _one_line_error(*_run(capsys, root, old)[::2])
    assert "no per-query outcomes" in err and "--force" in err


def test_a_task_without_poses_or_not_a_revisit_task_is_refused() -> None:
    from safl_bench.tasks.spec import TaskSpec
    from safl_bench.tasks.task import Task

    positions = np.column_stack([np.arange(10.0), np.zeros(10)])
    spec = TaskSpec(id="Test/NoPoses-Revisit-v0", source="bev", sequence="00", protocol="revisit",
                    step=1, tp_radius_m=3.0, fp_radius_m=20.0, window_s=1.0)
    views = np.zeros((10, 8, 8), np.float32)
    task = Task.from_arrays(spec, positions=positions, times=np.arange(10.0), database=views,
                            queries=views)
    with pytest.raises(DataError, match="no ground-truth poses"):
        slam_cell.poses_of(task)
    paper = TaskSpec(id="Test/NoPoses-T1R1-v0", source="bev", sequence="00", condition="T1R1", step=1)
    with pytest.raises(ConfigError, match="revisit tasks"):
        slam_cell.poses_of(Task.from_arrays(paper, positions=positions, times=np.arange(10.0),
                                            database=views, queries=views))


def test_outcomes_keep_a_valid_match_per_query() -> None:
    from safl_bench.evaluation.metrics import outcomes

    o = outcomes([2.0, -np.inf], [True, False], [True, False], match=np.array([5, -1], np.int32))
    assert o.match is not None and o.match.dtype == np.int64 and o.match.tolist() == [5, -1]
    assert outcomes([1.0], [True], [True]).match is None
    for bad in ([-2, 0], [1], [0.5, 1.0]):
        with pytest.raises(DataError, match="match must be integers >= -1"):
            outcomes([2.0, 1.0], [True, True], [True, True], match=np.array(bad))


def test_run_slam_then_the_leaderboard_table_and_pictures(
        cell: tuple[Path, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    from safl_bench.leaderboard import slam_figures, slam_table
    from safl_bench.results.records import load_records

    root, results = cell
    monkeypatch.setattr(slam_cell, "DEPLOY_FROM", {TASK: OTHER, OTHER: TASK})
    monkeypatch.setenv("SAFL_HOME", str(tmp_path / "home"))
    code = cli_main(["run", "--method", "sad@1", "--task", TASK, "--bev-root", str(root),
                     "--results", str(results), "--slam", "--quiet"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert f"deployed: the lowest keeping 100 % precision on {OTHER}" in out and "95 % interval" in out
    records = [r for r in load_records(results)[0] if r.task.id == TASK]
    cells = slam_table.load_cells(records, results)
    assert [(c.method, c.mode, len(c.results)) for c in cells] == [("sad@1", "sequence", 5)]
    md = slam_table.slam_markdown("tiny", cells)
    assert md is not None and "| odometry alone |" in md and "| sad@1 | sequence |" in md
    # the row says how many of its false closures lie in the 3-20 m band the recall leaves out
    first = cells[0].results[0]
    o = records[0].results["sequence"].queries.outcomes()  # type: ignore[union-attr]
    band = 0 if first.threshold is None else int(
        ((o.match >= 0) & (o.confidence >= first.threshold) & (o.label == 0)).sum())
    assert cells[0].band == band
    assert (f"{first.closures_false} ({band} in 3–20 m)" in md) == (first.closures_false > 0)
    assert json.loads(slam_table.slam_json(cells))[0]["ate_least-squares"][0] == pytest.approx(
        np.mean(cells[0].ate("least-squares")))
    # other settings never enter the table
    assert slam_table.load_cells(records, tmp_path) == []
    # pictures: the cell, the curves, the table's bars
    from safl_bench.tasks.registry import runnable_spec
    from safl_bench.tasks.task import Task

    task = Task.from_spec(runnable_spec(TASK), bev_root=str(root), progress=False)
    record = records[0]
    trajectories = slam_cell.cell_trajectories(record, task, slam_cell.SlamSettings(rpe_delta_m=10.0))
    assert set(trajectories.optimised) == {"least-squares", "cauchy", "gnc-tls"}
    for name, draw in (("cell.png", partial_draw(slam_figures.trajectory_figure, trajectories)),
                       ("curve.png", partial_draw(slam_figures.curve_figure, {"sad@1": slam_cell.threshold_curve(
                           record, task, slam_cell.SlamSettings(rpe_delta_m=10.0), 3)})),
                       ("bars.png", partial_draw(slam_figures.ate_bars, cells))):
        draw(tmp_path / name)
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"


def partial_draw(function, first):  # type: ignore[no-untyped-def]
    return lambda path: function(first, path)


def test_the_benchmark_cell_is_kitti00_sized() -> None:
    from safl_bench.bench import slam_bench

    poses, query, match, true = slam_bench.kitti00_sized_cell()
    assert poses.shape == (4541, 3) and len(query) == len(match) == 320 and true.sum() == 300
    distance = np.hypot(*(poses[query, :2] - poses[match, :2]).T)
    assert (distance[true] < 1.0).all() and (distance[~true] > 50).all()
