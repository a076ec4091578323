"""The retrieval method kind: the harness's candidate rule, tie rule, Recall@N and relative poses
for a method that answers queries with ranked candidates instead of descriptors; its records
(single-frame only, sequence n/a), the run table, and `check_method` on the kind."""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest
from test_evaluation import revisit_truth
from test_evaluation_values import MatrixMethod

from safl_bench.errors import ConfigError, DataError
from safl_bench.evaluation import evaluate_method
from safl_bench.groundtruth import GroundTruth
from safl_bench.methods.check import MethodCheckError, check_method
from safl_bench.methods.method import register_method, unregister_method
from safl_bench.methods.retrieval import NO_SEQUENCE, NOT_RETRIEVED, Retrieval, RetrievalMethod
from safl_bench.metrics import outcomes
from safl_bench.results.records import QueryOutcomes


class ScoreRetrieval(RetrievalMethod):
    """Views are frame numbers; query i's candidates are the `k` database frames of highest
    confidence C[i, j] (ties: the later frame first, to show the harness re-ranks), each with
    the pose [j, -j, 0.1]; `extra` frames are listed whatever the rule says."""

    name: ClassVar[str] = "score_retrieval"
    version: ClassVar[str] = "1"

    def __init__(self, C: Any = None, k: int = 3, extra: Any = None) -> None:
        self.C = C
        self.k = k
        self.extra = extra
        self.calls: list[dict[str, Any]] = []

    def retrieve(self, queries: Any, database: Any, *, db_limit: Any = None,
                 same_frames: bool = False) -> Retrieval:
        self.calls.append({"db_limit": db_limit, "same_frames": same_frames})
        index, conf, pose = [], [], []
        for q in np.asarray(queries, int):
            row = self.C[q, np.asarray(database, int)]
            order = np.lexsort((-np.arange(len(row)), -row))[:self.k]
            picked = [int(j) for j in order] + [int(j) for j in (self.extra or {}).get(int(q), [])
                                                if j not in order]
            index.append(picked)
            conf.append([float(row[j]) for j in picked])
            pose.append([[float(j), -float(j), 0.1] for j in picked])
        return Retrieval.from_lists(index, conf, pose=pose, seconds=[0.001] * len(index))


def line_truth(n: int) -> GroundTruth:
    xy = np.c_[np.arange(n) * 10.0, np.zeros(n)]
    return GroundTruth(xy, xy, np.zeros(n), np.zeros(n), tp_radius=1.0, fp_radius=1.0)


def test_only_single_frame_is_scored_and_recall_at_n_matches_a_descriptor_method_on_the_same_scores() -> None:
    rng = np.random.default_rng(3)
    n = 12
    C = rng.integers(0, 5, (n, n)).astype(float)  # many ties
    truth = line_truth(n)
    retr = evaluate_method(ScoreRetrieval(C, k=n), np.arange(n), np.arange(n), truth)
    desc = evaluate_method(MatrixMethod(-C), np.arange(n), np.arange(n), truth)
    assert set(retr.metrics) == {"single_frame"}
    r, d = retr.metrics["single_frame"], desc.metrics["single_frame"]
    assert r.recall_at_1 == d.recall_at_1
    assert r.recall_at_n[1] == d.recall_at_n[1] and r.recall_at_n[5] == d.recall_at_n[5]
    assert retr.outcomes["single_frame"].match.tolist() == desc.outcomes["single_frame"].match.tolist()
    assert retr.query_s is not None and len(retr.query_s) == n


def test_recall_at_1_is_the_single_frame_recall_when_some_queries_get_no_answer() -> None:
    n = 8
    C = np.eye(n) * 3.0
    C[2, 5] = 4.0  # query 2 answers a wrong frame
    method = ScoreRetrieval(C, k=1)
    method.k = 1
    ev = evaluate_method(method, np.arange(n), np.arange(n), line_truth(n))
    m = ev.metrics["single_frame"]
    assert m.recall_at_n[1] == m.recall_at_1 == 7 / 8
    silent = ScoreRetrieval(np.zeros((n, n)), k=0)
    m0 = evaluate_method(silent, np.arange(n), np.arange(n), line_truth(n)).metrics["single_frame"]
    assert m0.recall_at_n[1] == m0.recall_at_1 == 0.0  # frame 0 is not "found" by the tie rule


def test_equal_confidences_go_to_the_lower_database_index() -> None:
    C = np.zeros((3, 3))
    C[:, 1] = C[:, 2] = 5.0  # the method lists 2 before 1
    ev = evaluate_method(ScoreRetrieval(C, k=2), np.arange(3), np.arange(3), line_truth(3))
    assert ev.matches["single_frame"].index.tolist() == [1, 1, 1]


def test_frames_the_query_may_not_match_are_dropped_before_scoring() -> None:
    truth = revisit_truth()  # queries 5-9 may match frames 0-4 only
    C = np.zeros((10, 10))
    C[np.arange(10), np.arange(10)] = 100.0  # each frame's best candidate is itself: forbidden
    C[5, 0] = C[6, 1] = C[9, 4] = 10.0
    method = ScoreRetrieval(C, k=10)
    ev = evaluate_method(method, np.arange(10), np.arange(10), truth, revisit=True)
    assert method.calls[0]["same_frames"] is True
    assert method.calls[0]["db_limit"].tolist() == truth.db_limit().tolist()
    matched = ev.outcomes["single_frame"].match.tolist()
    assert matched[:5] == [-1] * 5  # no candidate at all
    assert matched[5] == 0 and matched[6] == 1 and matched[9] == 4


def test_a_query_answered_by_nothing_reports_no_match_and_ranks_true_places_after_the_list() -> None:
    C = np.zeros((4, 4))
    method = ScoreRetrieval(C, k=0, extra={1: [3]})
    ev = evaluate_method(method, np.arange(4), np.arange(4), line_truth(4))
    o = ev.outcomes["single_frame"]
    assert o.match.tolist() == [-1, 3, -1, -1]
    assert np.isneginf(o.confidence[[0, 2, 3]]).all()
    # a true place the method did not return is found at no N (rank beyond every list), even
    # where the tie rule among the frames left out would put it first (query 0, frame 0)
    assert o.true_rank.tolist() == [NOT_RETRIEVED] * 4
    assert ev.metrics["single_frame"].recall_at_n == {1: 0.0, 5: 0.0, 10: 0.0}


def test_the_matched_frames_relative_pose_is_recorded_and_descriptor_methods_have_none() -> None:
    n = 5
    C = np.eye(n) * 7
    ev = evaluate_method(ScoreRetrieval(C, k=2), np.arange(n), np.arange(n), line_truth(n))
    pose = ev.outcomes["single_frame"].relative_pose
    assert pose.tolist() == [[float(j), -float(j), 0.1] for j in range(n)]
    desc = evaluate_method(MatrixMethod(-C), np.arange(n), np.arange(n), line_truth(n))
    assert desc.outcomes["single_frame"].relative_pose is None
    stored = QueryOutcomes.of(ev.outcomes["single_frame"])
    assert stored.relative_pose[2] == [2.0, -2.0, 0.1]
    assert np.array_equal(stored.outcomes().relative_pose, pose)


def test_relative_pose_round_trips_none_rows_and_rejects_half_rows() -> None:
    o = outcomes([1.0, -np.inf], [True, False], [True, True],
                 relative_pose=[[1.0, 2.0, 0.5], [np.nan] * 3])
    stored = QueryOutcomes.of(o)
    assert stored.relative_pose == [[1.0, 2.0, 0.5], None]
    assert np.isnan(stored.outcomes().relative_pose[1]).all()
    with pytest.raises(DataError, match="all NaN"):
        outcomes([1.0], [True], [True], relative_pose=[[1.0, np.nan, 0.0]])
    with pytest.raises(DataError, match="shape"):
        outcomes([1.0], [True], [True], relative_pose=[[1.0, 2.0]])


def test_bad_answers_are_one_line_errors() -> None:
    with pytest.raises(DataError, match="outside the database"):
        Retrieval.from_lists([[5]], [[1.0]]).checked(1, 3, "m")
    with pytest.raises(DataError, match="twice"):
        Retrieval.from_lists([[1, 1]], [[1.0, 2.0]]).checked(1, 3, "m")
    with pytest.raises(DataError, match="finite"):
        Retrieval.from_lists([[1]], [[np.nan]]).checked(1, 3, "m")
    with pytest.raises(DataError, match=r"\(Nq=2"):
        Retrieval.from_lists([[1]], [[1.0]]).checked(2, 3, "m")
    with pytest.raises(ConfigError, match="retrieval method"):
        ScoreRetrieval().describe(np.zeros((1, 4, 4)))


class Blobs(RetrievalMethod):
    """A real (tiny) retrieval method for check_method: candidates by correlation of top views,
    a confidence of 100 * correlation; with same_frames only earlier frames (when `cheat`, the
    frame itself too)."""

    name: ClassVar[str] = "blobs"
    version: ClassVar[str] = "1"

    def __init__(self, cheat: bool = False) -> None:
        self.cheat = cheat

    def retrieve(self, queries: Any, database: Any, *, db_limit: Any = None,
                 same_frames: bool = False) -> Retrieval:
        q = np.asarray(queries, float).reshape(len(queries), -1)
        d = np.asarray(database, float).reshape(len(database), -1)
        q = (q - q.mean(1, keepdims=True)) / (q.std(1, keepdims=True) + 1e-9)
        d = (d - d.mean(1, keepdims=True)) / (d.std(1, keepdims=True) + 1e-9)
        corr = q @ d.T / q.shape[1]
        index, conf = [], []
        for i, row in enumerate(corr):
            allowed = range(i + (1 if self.cheat else 0)) if same_frames else range(len(row))
            picked = sorted(allowed, key=lambda j: -row[j])[:3]
            index.append(picked)
            conf.append([round(100 * float(row[j]), 6) for j in picked])
        return Retrieval.from_lists(index, conf)


def test_check_method_passes_a_conforming_retrieval_method_and_names_the_failed_check() -> None:
    check_method(Blobs())
    with pytest.raises(MethodCheckError, match=r"^\[same-frames-earlier\]"):
        check_method(Blobs(cheat=True))


def test_a_retrieval_record_has_no_sequence_result_and_the_run_table_says_why(
        bev_root: Path, safl_home: Path, tmp_path: Path) -> None:
    from safl_bench import tasks
    from safl_bench.results.records import load_record
    from safl_bench.run import runner

    register_method(Blobs)
    tasks.register("Test/RetrRevisit-v0", source="bev", sequence="00", protocol="revisit",
                   window_s=5.0, map_config=None)
    try:
        options = runner.RunOptions(results_dir=tmp_path / "r", bev_root=str(bev_root),
                                    progress=False)
        outcome = runner.run_cell(Blobs(), "Test/RetrRevisit-v0", options)
        record = load_record(outcome.path)
        assert set(record.results) == {"single_frame"}
        assert record.method.kind == "retrieval"
        assert "retrieval method" in record.timings.how_run
        table = runner.summary_table([outcome])
        assert NO_SEQUENCE in table and "no difference matrix" in table
    finally:
        tasks.unregister("Test/RetrRevisit-v0")
        unregister_method("blobs")


def test_leaderboard_tables_say_the_sequence_matcher_is_na_for_a_retrieval_method() -> None:
    import dataclasses

    from record_factory import make_record

    from safl_bench.leaderboard.grouping import group_records
    from safl_bench.leaderboard.tables import recall_table

    retrieval = make_record("map_closures", recall=0.4, modes=("single_frame",))
    retrieval = dataclasses.replace(retrieval, method=dataclasses.replace(retrieval.method,
                                                                         kind="retrieval"))
    records = [make_record("sad", recall=0.3), retrieval]
    groups, notes = group_records(records)
    ((key, group),) = groups.items()
    md = recall_table(key, group, notes[key]).markdown()
    rows = [line for line in md.splitlines() if line.startswith("| map_closures")]
    assert len(rows) == 1 and "single-frame" in rows[0]
    assert "map_closures@1: sequence matcher n/a" in md
    only_descriptors = recall_table(*next(iter(group_records(records[:1])[0].items()))).markdown()
    assert "n/a" not in only_descriptors


def test_a_points_method_that_reads_top_views_runs_on_an_image_folder(
        bev_root: Path, safl_home: Path, tmp_path: Path) -> None:
    from safl_bench import tasks
    from safl_bench.errors import SaflError
    from safl_bench.run import runner

    class PointsFirst(Blobs):
        name: ClassVar[str] = "points_first"
        input_kind: ClassVar[str] = "points"
        reads_topview: ClassVar[bool] = True

    class PointsOnly(PointsFirst):
        name: ClassVar[str] = "points_only"
        reads_topview: ClassVar[bool] = False

    tasks.register("Test/RetrRevisitPts-v0", source="bev", sequence="00", protocol="revisit",
                   window_s=5.0, map_config=None)
    try:
        options = runner.RunOptions(results_dir=tmp_path / "r", bev_root=str(bev_root),
                                    progress=False)
        outcome = runner.run_cell(PointsFirst(), "Test/RetrRevisitPts-v0", options)
        assert outcome.record is not None and set(outcome.record.results) == {"single_frame"}
        with pytest.raises(SaflError, match="has no points views"):
            runner.run_cell(PointsOnly(), "Test/RetrRevisitPts-v0", options)
    finally:
        tasks.unregister("Test/RetrRevisitPts-v0")
