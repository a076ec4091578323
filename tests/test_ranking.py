"""The synthetic-against-real ranking comparison (`safl_bench.leaderboard.ranking`)."""

from __future__ import annotations

import math

import numpy as np

from safl_bench.leaderboard import ranking as R
from tests.record_factory import scored_record

SYN = R.Side("synthetic 00", ("SAFL/Synth00-Revisit-v4",))
REAL = R.Side("real 00", ("SAFL/BEVKITTI00-Revisit-v0",))


def test_tau_b_counts_ties_and_is_undefined_without_an_order() -> None:
    assert R.tau_b(np.array([1, 2, 3]), np.array([10, 20, 30])) == 1.0
    assert R.tau_b(np.array([1, 2, 3]), np.array([3, 2, 1])) == -1.0
    # one tie on the second side: (2 - 0) / sqrt(3 * 2)
    assert math.isclose(float(R.tau_b(np.array([1, 2, 3]), np.array([1, 1, 2]))), 2 / math.sqrt(6))
    assert math.isnan(float(R.tau_b(np.array([1, 2, 3]), np.array([5, 5, 5]))))
    batch = R.tau_b(np.array([[1, 2, 3], [3, 2, 1]]), np.array([[1, 2, 3], [1, 2, 3]]))
    assert batch.tolist() == [1.0, -1.0]


def _records(skills: dict[str, tuple[float, float | None]]) -> list:
    out = []
    for k, (m, (syn, real)) in enumerate(sorted(skills.items())):
        out.append(scored_record(m, skill=syn, variant=k, protocol="revisit", sequence="00",
                                 source_kind="synth", task_version=4))
        if real is not None:
            out.append(scored_record(m, skill=real, variant=k, protocol="revisit", sequence="00",
                                     source_kind="bev", source_label="KITTI top-view images",
                                     task_version=0))
    return out


def test_reversed_orders_give_negative_tau_with_an_interval_and_name_what_is_left_out() -> None:
    records = _records({"a": (0.95, 0.2), "b": (0.6, 0.6), "c": (0.2, 0.95), "d": (0.5, None)})
    c = R.compare(records, "revisit", SYN, REAL, "single_frame", "recall_at_1")
    assert c.methods == ["a@1", "b@1", "c@1"]
    assert c.left_out == {"d@1": "no record on SAFL/BEVKITTI00-Revisit-v0"}
    assert c.order(SYN) == ["a@1", "b@1", "c@1"] and c.order(REAL) == ["c@1", "b@1", "a@1"]
    assert c.tau is not None and c.tau.mean == -1.0
    assert c.tau.low <= c.tau.mean <= c.tau.high and c.tau.high < 0
    assert c.disagree >= 1 and c.agree == 0
    data = c.to_json()
    assert data["tau"]["value"] == -1.0 and data["order"]["real 00"][0] == "c@1"


def test_same_orders_agree() -> None:
    records = _records({"a": (0.95, 0.9), "b": (0.5, 0.45), "c": (0.1, 0.1)})
    c = R.compare(records, "revisit", SYN, REAL, "sequence", "recall_at_1")
    assert c.tau is not None and c.tau.mean == 1.0 and c.agree >= 1 and c.disagree == 0
    assert "tau-b" in R.markdown([c]) and R.summary_rows([c])[1][3].startswith("a ")


def test_repeated_runs_of_an_unseedable_method_are_its_cell_not_missing_seeds() -> None:
    """MapClosures-style: a method that cannot be seeded runs a task where nothing is random 3
    times (seeds 0-2); the comparison reads them as that cell's runs, as the tables do."""
    records = _records({"a": (0.95, 0.9), "b": (0.5, 0.45)})
    for side in ({"source_kind": "synth", "task_version": 4},
                 {"source_kind": "bev", "source_label": "KITTI top-view images", "task_version": 0}):
        for run in range(3):
            skill = 0.2 if side["source_kind"] == "synth" else 0.15
            records.append(scored_record("u", seed=run, skill=skill, variant=9, protocol="revisit",
                                         sequence="00", deterministic=False, **side))
    c = R.compare(records, "revisit", SYN, REAL, "single_frame", "recall_at_1")
    assert c.methods == ["a@1", "b@1", "u@1"] and not c.left_out
    assert c.values["u@1"][SYN.label].n_seeds == 3  # its runs, drawn as seeds
    assert c.order(SYN) == ["a@1", "b@1", "u@1"]
    # a seedable method's extra seeds on such a task are not repeats: still named as missing
    extra = [*records, scored_record("a", seed=1, skill=0.9, variant=0, protocol="revisit",
                                     sequence="00", source_kind="synth", task_version=4)]
    left = R.compare(extra, "revisit", SYN, REAL, "single_frame", "recall_at_1").left_out
    assert left == {"a@1": "seeds [0, 1] of [0] on SAFL/Synth00-Revisit-v4"}
