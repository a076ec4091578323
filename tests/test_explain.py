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
    window = outcome.record.matcher["enhancement"]["window"]  # the dip rule's, recorded
    np.testing.assert_array_equal(ex.enhanced, matching.enhanced_matrix(
        ex.D, ex.config.sequence, enhance_window=window))
    assert ex.result.enhance_window == window and ex.true_rank is not None
    assert "contrast enhancement (window" in explain.summary(ex)
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


@pytest.fixture
def tiny_retrieval(kitti_root: Path, safl_home: Path) -> Iterator[str]:
    """A tiny task whose first 2 queries are context (outside the record's outcomes), and the
    test retrieval method of tests/test_retrieval.py registered (no map-closures package)."""
    from test_retrieval import Blobs

    from safl_bench.methods.method import register_method, unregister_method

    task_id = "Test/TinyExplainRetrieval-T20R2-v0"
    tasks.register(task_id, source="kitti", sequence="00", condition="T20R2", step=1,
                   map_config=MapConfig(size=32), context_queries=2)
    register_method(Blobs)
    yield task_id
    unregister_method("blobs")
    tasks.unregister(task_id)


def test_a_retrieval_cell_is_explained_from_its_record_without_running_the_method(
        tiny_retrieval, kitti_root, tmp_path, capsys, monkeypatch):
    from matplotlib.axes import Axes
    from test_retrieval import Blobs

    outcome = runner.run_cell(Blobs(), tiny_retrieval, options(kitti_root, tmp_path))
    stored = outcome.record.results["single_frame"].queries
    assert stored is not None and stored.match is not None

    def no_rerun(*args: object, **kw: object) -> None:
        raise AssertionError("explain ran the retrieval method again")

    monkeypatch.setattr(Blobs, "retrieve", no_rerun)
    ex = explain.explain("blobs", tiny_retrieval, options(kitti_root, tmp_path), top=4)
    assert ex.mode == "single_frame" and ex.retrieval
    assert ex.D is None and ex.enhanced is None
    # the record's matches and confidences, placed after the 2 context queries
    assert ex.result.index[:2].tolist() == [-1, -1]
    assert ex.result.index[2:].tolist() == stored.match
    assert ex.confidence[2:].tolist() == [-np.inf if c is None else c for c in stored.confidence]
    assert (ex.status[:2] == explain.NOT_SCORED).all()
    labels = {1: explain.CORRECT, -1: explain.WRONG, 0: explain.BAND}
    assert [str(s) for s in ex.status[2:]] == [labels[v] if m >= 0 else explain.NO_MATCH
                                               for v, m in zip(stored.label, stored.match, strict=True)]
    assert ex.metrics.recall_at_100 == pytest.approx(ex.recorded_recall)
    assert ex.worst and all(ex.status[i] == explain.WRONG for i in ex.worst)

    texts: list[str] = []
    images: list[tuple[int, ...]] = []
    text, imshow = Axes.text, Axes.imshow

    def noted_text(self, x, y, s, *args, **kw):
        texts.append(s)
        return text(self, x, y, s, *args, **kw)

    def noted_imshow(self, X, *args, **kw):
        images.append(np.shape(X))
        return imshow(self, X, *args, **kw)

    monkeypatch.setattr(Axes, "text", noted_text)
    monkeypatch.setattr(Axes, "imshow", noted_imshow)
    out = tmp_path / "retrieval.png"
    assert main(["explain", "--method", "blobs", "--task", tiny_retrieval, "--kitti-root",
                 str(kitti_root), "--results", str(tmp_path), "--out", str(out), "--quiet"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert any("No difference matrix" in t and "blobs is a retrieval method" in t for t in texts)
    # no matrix is drawn, only the top views of the most confident wrong match: query, wrong
    # match, true frame (every query of this task has one)
    assert len(images) == 3 * len(ex.worst) and all(shape == (32, 32) for shape in images)
    printed = capsys.readouterr().out
    assert "its own top candidates" in printed and str(out) in printed


def test_the_sequence_mode_of_a_retrieval_method_is_a_one_line_error(tiny_retrieval, kitti_root,
                                                                     tmp_path, capsys):
    from safl_bench.errors import ConfigError

    with pytest.raises(ConfigError, match="the sequence matcher does not apply to retrieval methods"):
        explain.explain("blobs", tiny_retrieval, options(kitti_root, tmp_path), mode="sequence")
    assert main(["explain", "--method", "blobs", "--task", tiny_retrieval, "--mode", "sequence",
                 "--kitti-root", str(kitti_root), "--results", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the sequence matcher does not apply to retrieval methods" in err[0]


def test_explain_shows_a_descriptor_methods_single_frame_matches_on_request(tiny_task, kitti_root,
                                                                            tmp_path):
    runner.run_cell(make_method("sad"), tiny_task, options(kitti_root, tmp_path))
    ex = explain.explain("sad", tiny_task, options(kitti_root, tmp_path), mode="single_frame")
    assert ex.mode == "single_frame" and not ex.retrieval and ex.D is not None
    want = matching.match(ex.D, ex.config.single_frame)
    assert ex.result.index.tolist() == want.index.tolist()
    assert ex.metrics.recall_at_100 == pytest.approx(ex.recorded_recall)
    assert ex.recorded_recall == ex.record.results["single_frame"].metrics.recall_at_100_precision
