"""Long runs lose nothing and show progress: describing through the descriptor cache is
checkpointed in chunks (an interrupted describe, or cell, resumes from its last chunk), the
progress counts frames inside a cell, and where stderr is not a terminal a run writes one line
per finished cell instead of carriage-return redraws."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from safl_bench import runner, tasks
from safl_bench.common import progress
from safl_bench.mapconfig import MapConfig
from safl_bench.method import Method, as_topview
from safl_bench.method_registry import make_method
from safl_bench.methods import descriptor_cache
from safl_bench.methods.descriptor_cache import Chunking, cache_dir, cached_describe

FOURS = Chunking(first=4, most=4)  # fixed chunks of four frames


class Toy(Method):
    """Per-frame deterministic descriptors; raises KeyboardInterrupt (Ctrl-C) on describe call
    number `interrupt_at` (1-based), as a user would in the middle of a long describe."""

    name = "toy_checkpoint"
    version = "1"
    input_kind = "topview"
    cache_descriptors = True

    def __init__(self) -> None:
        self.calls: list[int] = []  # frames of each describe call
        self.interrupt_at: int | None = None

    def describe(self, maps):  # type: ignore[no-untyped-def]
        arr = as_topview(maps)
        self.calls.append(len(arr))
        if self.interrupt_at is not None and len(self.calls) == self.interrupt_at:
            raise KeyboardInterrupt
        flat = arr.reshape(len(arr), -1).astype(np.float64)
        return np.stack([flat.mean(1), flat.std(1), np.sin(flat).sum(1)], 1).astype(np.float32)


class Recorder:
    """A `FrameProgress` that keeps what it was told."""

    def __init__(self) -> None:
        self.expected: list[int] = []
        self.advanced: list[int] = []

    def expect(self, n: int) -> None:
        self.expected.append(n)

    def advance(self, n: int) -> None:
        self.advanced.append(n)


def views(n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).random((n, 8, 8)).astype(np.float32)


def test_an_interrupted_describe_resumes_from_its_last_chunk(safl_home, tmp_path, monkeypatch) -> None:
    frames = views(18)
    first = Toy()
    first.interrupt_at = 3  # two chunks done, Ctrl-C in the third
    with pytest.raises(KeyboardInterrupt):
        cached_describe(first, frames, FOURS)
    assert first.calls == [4, 4, 4]
    assert len(list(cache_dir(first).glob("shard-*.npz"))) == 2  # the finished chunks are kept
    assert not list(cache_dir(first).glob(".*"))  # and nothing half-written is left

    again = Toy()
    resumed, _, n = cached_describe(again, frames, FOURS)
    assert n == 10 and again.calls == [4, 4, 2]  # only what the interrupt lost and the rest

    monkeypatch.setenv("SAFL_HOME", str(tmp_path / "other-home"))
    whole, _, n = cached_describe(Toy(), frames, Chunking(first=100, most=100))  # one call
    assert n == 18
    assert resumed.tobytes() == whole.tobytes()  # bit-identical to describing in one call
    assert resumed.tobytes() == Toy().describe(frames).tobytes()


def test_seconds_per_frame_sum_what_each_chunk_cost_over_runs(safl_home) -> None:
    frames = views(10, seed=1)
    method = Toy()
    method.interrupt_at = 2
    with pytest.raises(KeyboardInterrupt):
        cached_describe(method, frames, FOURS)
    _, per_frame, n = cached_describe(Toy(), frames, FOURS)
    assert n == 6
    stored = []
    for path in cache_dir(method).glob("shard-*.npz"):
        with np.load(path) as data:
            stored.append((len(data["keys"]), float(data["seconds_per_frame"])))
    assert sorted(k for k, _ in stored) == [2, 4, 4]
    assert per_frame == pytest.approx(sum(k * s for k, s in stored) / 10)
    _, cached_cost, n = cached_describe(Toy(), frames, FOURS)  # all cached: the same cost
    assert n == 0 and cached_cost == pytest.approx(per_frame)


def test_a_cache_written_in_one_shard_before_chunking_still_reads(safl_home) -> None:
    frames = views(6, seed=2)
    method = Toy()
    keys = descriptor_cache.view_keys(frames)
    folder = cache_dir(method)
    folder.mkdir(parents=True)
    np.savez(folder / "shard-0123456789abcdef.npz", keys=keys, descriptors=method.describe(frames),
             seconds_per_frame=np.float64(0.25))
    out, per_frame, n = cached_describe(Toy(), frames, FOURS)
    assert n == 0 and per_frame == pytest.approx(0.25)
    np.testing.assert_array_equal(out, method.describe(frames))


def test_chunks_are_sized_by_time_within_bounds(safl_home) -> None:
    policy = Chunking(first=16, seconds=30.0, most=1024)
    assert policy.next_size(0.08) == 375  # BEVPlace's ~80 ms a frame: ~30 s a chunk
    assert policy.next_size(10.0) == 16  # a slow method: never fewer than `first`
    assert policy.next_size(1e-6) == 1024 and policy.next_size(0.0) == 1024  # a fast one
    plan = iter([7, 3, 100, 100])

    class Scripted(Chunking):
        def next_size(self, seconds_per_frame: float) -> int:
            assert seconds_per_frame >= 0  # what the chunk before measured
            return next(plan)

    method = Toy()
    cached_describe(method, views(20, seed=3), Scripted(first=4))
    assert method.calls == [4, 7, 3, 6]  # `first`, then what the policy asks after each chunk


def test_progress_counts_the_frames_of_a_cell(safl_home, monkeypatch) -> None:
    from safl_bench.evaluation import difference_matrix

    database, queries = views(9, seed=4), views(5, seed=5)
    cached_describe(Toy(), database[:3], FOURS)  # three already in the cache
    monkeypatch.setattr(descriptor_cache, "CHUNKING", FOURS)
    seen = Recorder()
    with progress.reporting(seen):
        difference_matrix(Toy(), queries, database)
    assert seen.expected == [14]
    assert seen.advanced == [3, 4, 2, 0, 4, 1]  # database: cached, two chunks; queries: two chunks
    assert sum(seen.advanced) == 14
    progress.advance(5)  # with nothing installed: nobody is told, nothing fails


# -- through the runner --------------------------------------------------------------------------

TASKS = ("Test/Checkpoint-T1R1-v0", "Test/Checkpoint-T5R1-v0")


@pytest.fixture
def tiny_tasks(kitti_root: Path, safl_home: Path) -> Iterator[tuple[str, ...]]:
    for task_id in TASKS:
        tasks.register(task_id, source="kitti", sequence="00", condition=task_id.split("-")[1],
                       step=1, map_config=MapConfig(size=32), n_seeds=1)
    yield TASKS
    for task_id in TASKS:
        tasks.unregister(task_id)


def run_options(kitti_root: Path, results: Path, progress_on: bool = True) -> runner.RunOptions:
    return runner.RunOptions(results_dir=results, kitti_root=str(kitti_root), progress=progress_on,
                             timing_frames=2, timing_repeats=1)


def test_an_interrupted_cell_resumes_from_its_last_chunk(tiny_tasks, kitti_root, tmp_path,
                                                        monkeypatch) -> None:
    monkeypatch.setattr(descriptor_cache, "CHUNKING", FOURS)
    task = [tiny_tasks[0]]
    first = Toy()
    first.interrupt_at = 5  # the database's three chunks, one of the queries', then Ctrl-C
    with pytest.raises(KeyboardInterrupt):
        runner.run_grid([first], task, run_options(kitti_root, tmp_path / "a", False))
    assert first.calls == [4, 4, 4, 4, 4]
    again = Toy()
    [out] = runner.run_grid([again], task, run_options(kitti_root, tmp_path / "a", False))
    assert out.status == "computed" and out.record is not None
    assert [n for n in again.calls if n > 1] == [4, 4]  # the queries' two last chunks, then timing
    assert set(again.calls[2:]) == {1}  # batch-1 timing

    monkeypatch.setenv("SAFL_HOME", str(tmp_path / "fresh-home"))  # described from nothing
    [whole] = runner.run_grid([Toy()], task, run_options(kitti_root, tmp_path / "b", False))
    assert whole.record is not None
    assert repr(out.record.results) == repr(whole.record.results)  # matches, outcomes, metrics


def test_a_log_gets_one_line_per_finished_cell_and_no_carriage_returns(tiny_tasks, kitti_root,
                                                                       tmp_path, capsys) -> None:
    outcomes = runner.run_grid([make_method("sad")], list(tiny_tasks),
                               run_options(kitti_root, tmp_path))  # stderr captured: not a terminal
    assert [o.status for o in outcomes] == ["computed", "computed"]
    err = capsys.readouterr().err
    assert "\r" not in err
    cell_lines = [line for line in err.splitlines() if re.match(r"^\[\d+/\d+\] ", line)]
    assert len(cell_lines) == 2
    for k, (line, task_id) in enumerate(zip(cell_lines, tiny_tasks, strict=True), 1):
        assert line.startswith(f"[{k}/2] {task_id} seed 0: computed in ")
        assert line.endswith(" s (24 frames)")  # 12 database and 12 query frames
    runner.run_grid([make_method("sad")], list(tiny_tasks), run_options(kitti_root, tmp_path, False))
    assert capsys.readouterr().err == ""  # --quiet: not a line


def test_a_terminal_gets_bars_over_cells_and_frames(tiny_tasks, kitti_root, tmp_path, capsys,
                                                   monkeypatch) -> None:
    monkeypatch.setattr(progress, "interactive", lambda stream: True)
    runner.run_grid([make_method("sad")], [tiny_tasks[0]], run_options(kitti_root, tmp_path))
    err = capsys.readouterr().err
    assert "\r" in err and "cell" in err
    # a bar over the cell's 24 frames under the grid's (a fast method's cell ends before it
    # redraws; `test_progress_counts_the_frames_of_a_cell` checks what it is told)
    assert re.search(r"Checkpoint-T1R1-v0 frames: +0%\|.*\| 0/24 .*frame/s", err)
    assert not re.search(r"^\[\d+/\d+\] ", err, re.MULTILINE)


def test_a_parallel_run_logs_a_line_per_cell_as_it_comes_back(tiny_tasks, kitti_root, tmp_path,
                                                              capsys, monkeypatch) -> None:
    from safl_bench.common.parallel import JobResult, Parallel

    # the workers stood in for by this process (real ones take seconds to start), finishing
    # the cells in the reverse order
    real_prepare = runner.prepare_tasks
    monkeypatch.setattr(runner, "prepare_tasks",
                        lambda tasks_, kinds, parallel=None, progress=True: real_prepare(
                            tasks_, kinds, parallel=None, progress=progress))

    def run_jobs(fn, jobs, parallel, *, on_done=None):  # type: ignore[no-untyped-def]
        results = [JobResult(None)] * len(jobs)
        for j in reversed(range(len(jobs))):
            results[j] = JobResult(fn(*jobs[j]))
            on_done(j, results[j])
        return results

    monkeypatch.setattr(runner, "run_jobs", run_jobs)
    outcomes = runner.run_grid([make_method("sad")], list(tiny_tasks),
                               run_options(kitti_root, tmp_path), parallel=Parallel(workers=2))
    assert [o.status for o in outcomes] == ["computed", "computed"]
    err = capsys.readouterr().err
    assert "\r" not in err
    cell_lines = [line for line in err.splitlines() if re.match(r"^\[\d+/\d+\] ", line)]
    assert cell_lines == [f"[1/2] {tiny_tasks[1]} seed 0: evaluated",  # counted as they come back
                          f"[2/2] {tiny_tasks[0]} seed 0: evaluated"]


def test_chunks_described_on_workers_equal_one_describe_and_fill_the_cache(safl_home) -> None:
    """What a cell spread over a cluster does (`describe_chunks`, `cached_describe(parallel=)`;
    run in this process here): the same descriptors as one call, a shard per chunk, progress
    per chunk; point clouds (a list) are cut by item."""
    from safl_bench.common.parallel import Parallel

    here = Parallel(workers=1)  # the jobs' code path, without starting processes
    toy = Toy()
    v = views(10)
    got, per_frame, fresh = cached_describe(toy, v, parallel=here)
    assert fresh == 10 and toy.calls == [5, 5]  # two chunks a slot
    np.testing.assert_array_equal(got, Toy().describe(v), strict=True)
    assert per_frame > 0 and len(list(cache_dir(toy).glob("shard-*.npz"))) == 2
    again, _, fresh = cached_describe(Toy(), v)
    assert fresh == 0 and np.array_equal(again, got)

    m2dp = make_method("m2dp")
    rng = np.random.default_rng(1)
    clouds = [rng.standard_normal((200 + 10 * i, 3)).astype(np.float32) for i in range(5)]
    seen = Recorder()
    with progress.reporting(seen):
        pieces = descriptor_cache.describe_chunks(m2dp, clouds, here)
    assert [len(p[0]) for p in pieces] == [3, 2] and seen.advanced == [3, 2]
    np.testing.assert_array_equal(np.concatenate([p[0] for p in pieces]),
                                  np.asarray(m2dp.describe(clouds), np.float32), strict=True)
