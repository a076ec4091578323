"""Tasks: registry rules, built-in suites, noise distribution, determinism, T0R0, missing data."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from scipy import stats

import safl_bench  # noqa: F401  (registers the built-in tasks)
from safl_bench import tasks
from safl_bench.cli import main as cli_main
from safl_bench.errors import ConfigError, DataError, RegistryError
from safl_bench.mapbuild import build_views
from safl_bench.mapconfig import MapConfig
from safl_bench.noise import CLEAN, PAPER_CONDITIONS, Condition, sample_offsets
from safl_bench.tasks import TaskSpec
from safl_bench.tasks.builtin import SYNTH_DATA_VERSIONS, TASK_VERSION, superseded

PINNED = Path(tasks.__file__).parent / "fingerprints.json"
TINY_MAP = MapConfig(size=32)


@pytest.fixture
def temp_register() -> Iterator[Callable[..., TaskSpec]]:
    """Register tasks for one test; they are removed afterwards."""
    added: list[str] = []

    def add(task_id: str, **fields: object) -> TaskSpec:
        spec = tasks.register(task_id, **fields)
        added.append(spec.id)
        return spec

    yield add
    for task_id in added:
        tasks.unregister(task_id)


# ---------------------------------------------------------------- registry


def test_builtin_suites_cover_the_paper_and_revisit() -> None:
    paper = tasks.suite("paper", source="synth")
    assert paper == [f"SAFL/Synth00-{c.name}-v6" for c in PAPER_CONDITIONS]
    full_kitti = tasks.suite("paper-full", source="kitti")
    for seq in ("00", "09"):
        assert [f"SAFL/KITTI{seq}-{c.name}-v1" for c in PAPER_CONDITIONS] == [
            i for i in full_kitti if i.startswith(f"SAFL/KITTI{seq}")
        ]
    assert set(tasks.suite("revisit")) == {
        "SAFL/Synth00-Revisit-v6",
        "SAFL/Synth09-Revisit-v6",
        "SAFL/KITTI00-Revisit-v0",
        "SAFL/KITTI05-Revisit-v0",
        "SAFL/KITTI08-Revisit-v0",
        *(f"SAFL/BEVKITTI{seq}-Revisit-v0" for seq in ("00", "02", "05", "06")),
    }
    assert set(tasks.suite("all")) >= set(full_kitti) | set(tasks.suite("revisit"))
    spec = tasks.spec("SAFL/KITTI08-Revisit-v0")
    assert (spec.tp_radius_m, spec.fp_radius_m, spec.window_s, spec.condition) == (
        3.0,
        20.0,
        30.0,
        CLEAN,
    )
    spec = tasks.spec("SAFL/Synth09-T20R2-v6")
    assert (spec.condition, spec.step, spec.tp_radius_m, spec.window_s) == (
        Condition(20, 2),
        4,
        10.0,
        None,
    )
    with pytest.raises(RegistryError, match="Did you mean: paper"):
        tasks.suite("papr")


def test_run_help_names_every_suite(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        cli_main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for name in tasks.SUITES:
        assert name in text, name


def test_builtin_tasks_are_registered_with_gymnasium_lazily() -> None:
    for task_id in tasks.suite("all"):
        env_spec = gymnasium.spec(task_id)
        assert env_spec.entry_point == "safl_bench.tasks.env:TaskEnv"
        assert env_spec.kwargs == {"task_id": task_id}


def test_builtin_definitions_match_their_pinned_fingerprints() -> None:
    """A changed definition must get a new version: v0's fingerprint never changes (superseded
    versions, in no suite, included)."""
    pinned = json.loads(PINNED.read_text())
    builtin = [*tasks.suite("all"), *superseded()]
    current = {i: tasks.registry[i].fingerprint for i in builtin}
    changed = sorted(i for i in pinned if i in current and current[i] != pinned[i])
    assert not changed, f"definitions changed without a new version: {changed}"
    assert set(pinned) == set(current)


def test_unknown_ids_suggest_close_ones() -> None:
    with pytest.raises(RegistryError, match=r"Did you mean: SAFL/KITTI00-T5R1\.5-v0"):
        tasks.spec("SAFL/KITI00-T5R1.5-v0")
    with pytest.raises(RegistryError, match="unknown task"):
        tasks.make("nothing like it")
    with pytest.raises(RegistryError, match="no version v7; registered versions: v0, v1, v2, v3, v4, v5, v6"):
        tasks.spec("SAFL/Synth00-T1R1-v7")
    with pytest.raises(RegistryError, match="no version v5; registered versions: v0, v1, v2, v3, v4, v6"):
        tasks.spec("SAFL/Synth00-Revisit-v5")  # skipped: v6 is data version 6 in both protocols


def test_duplicates_versions_and_fingerprints(temp_register: Callable[..., TaskSpec]) -> None:
    v0 = temp_register("Test/Thing-T1R1-v0", source="synth", sequence="00", condition="T1R1")
    with pytest.raises(RegistryError, match="already registered"):
        tasks.register("Test/Thing-T1R1-v0", source="synth", sequence="00")
    v1 = temp_register(
        "Test/Thing-T1R1-v1", source="synth", sequence="00", condition="T1R1", step=2
    )
    assert v1.fingerprint != v0.fingerprint
    assert replace(v0, id="Test/Other-v4").fingerprint == v0.fingerprint  # name-independent
    with pytest.warns(UserWarning, match="latest version Test/Thing-T1R1-v1"):
        assert tasks.spec("Test/Thing-T1R1") is v1
    with pytest.warns(UserWarning, match="superseded by Test/Thing-T1R1-v1"):
        assert tasks.spec("Test/Thing-T1R1-v0") is v0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert tasks.spec("Test/Thing-T1R1-v1") is v1
    assert "Test/Thing-T1R1-v1" in gymnasium.registry


# ---------------------------------------------------------------- synthetic data version

#: Fingerprints from before synthetic data version "2" (commit 6ec0f55): they must not move.
KITTI_T1R1_V0 = "a0fa7aa13e7f9750"
BEV_REVISIT_V0 = "0ae6af3f5d4e9f33"
SYNTH_T1R1_V0 = "27a410ed7134eecf"
#: ... nor that of the synthetic tasks' v1, on data version "2" (commit 4986ce8).
SYNTH_T1R1_V1 = "fa985fbdcacbb498"
#: ... nor that of v2, on data version "3" (commit c4f33da).
SYNTH_T1R1_V2 = "e9fbed849f9b9d5c"
#: ... nor that of v3, on data version "4" (commit 4bda4bb).
SYNTH_T1R1_V3 = "b9607d4916279bcc"


def test_synthetic_tasks_name_their_data_version_in_the_fingerprint() -> None:
    from safl_bench.synth import GENERATOR_VERSION

    assert TASK_VERSION["paper"]["synth"] == max(SYNTH_DATA_VERSIONS)
    assert SYNTH_DATA_VERSIONS[TASK_VERSION["paper"]["synth"]] == GENERATOR_VERSION == "6"
    assert SYNTH_DATA_VERSIONS[TASK_VERSION["revisit"]["synth"]] == GENERATOR_VERSION
    old, mid, v2, v3, new = (tasks.registry[f"SAFL/Synth00-T1R1-v{v}"] for v in (0, 1, 2, 3, 4))
    assert (old.data_version, mid.data_version, v2.data_version, v3.data_version,
            new.data_version) == ("1", "2", "3", "4", "5")
    assert new.definition()["data_version"] == "5" and new.to_dict()["data_version"] == "5"
    v6 = tasks.registry["SAFL/Synth00-T1R1-v6"]
    assert v6.definition()["data_version"] == "6"
    assert tasks.registry["SAFL/Synth09-Revisit-v6"].data_version == "6"
    assert tasks.registry["SAFL/Synth09-Revisit-v4"].data_version == "5"
    assert v3.definition()["data_version"] == "4" and v3.fingerprint == SYNTH_T1R1_V3
    assert v2.definition()["data_version"] == "3" and v2.fingerprint == SYNTH_T1R1_V2
    assert mid.definition()["data_version"] == "2"
    assert "data_version" not in old.definition()  # v0 predates the field: its print stays
    assert old.fingerprint == SYNTH_T1R1_V0 and mid.fingerprint == SYNTH_T1R1_V1
    assert len({old.fingerprint, mid.fingerprint, v2.fingerprint, v3.fingerprint, new.fingerprint}) == 5
    assert {k: v for k, v in new.definition().items() if k != "data_version"} == old.definition()
    for superseded_id in superseded():
        name = superseded_id.rsplit("-v", 1)[0]
        current = next(i for i in tasks.suite("all") if i.rsplit("-v", 1)[0] == name)
        assert tasks.registry[current].fingerprint != tasks.registry[superseded_id].fingerprint
    # a synthetic task registered without one is on the data this safl-bench generates
    assert TaskSpec(id="Test/A-v0", source="synth", sequence="00").data_version == GENERATOR_VERSION
    with pytest.raises(ConfigError, match="synthetic tasks only"):
        TaskSpec(id="Test/A-v0", source="kitti", sequence="00", data_version="2")


def test_real_data_fingerprints_are_unchanged() -> None:
    assert tasks.registry["SAFL/KITTI00-T1R1-v0"].fingerprint == KITTI_T1R1_V0
    assert tasks.registry["SAFL/BEVKITTI00-Revisit-v0"].fingerprint == BEV_REVISIT_V0
    for task_id in tasks.suite("all"):
        spec = tasks.registry[task_id]
        if spec.source != "synth":
            assert spec.version == (0 if spec.protocol == "revisit" else 1)
            assert spec.data_version is None
            assert "data_version" not in spec.definition()


def test_suites_hold_only_the_current_versions() -> None:
    old_data = [i for i, s in tasks.registry.items()
                if i.startswith("SAFL/Synth") and s.version in (0, 1, 2, 3)]
    scored_every_query = [i for i, s in tasks.registry.items() if i.startswith("SAFL/")
                          and s.protocol in ("paper", "bevplace") and not s.context_queries
                          and i not in old_data]
    data_5 = [i for i, s in tasks.registry.items() if i.startswith("SAFL/Synth")
              and s.data_version == "5" and s.context_queries + (s.protocol == "revisit") > 0]
    assert sorted(superseded()) == sorted(old_data + scored_every_query + data_5)
    assert len(data_5) == 26 + 2  # paper v5 (2 x 13) and revisit v4, on data version 5
    assert len(old_data) == 112  # 4 old versions x (2 x (12 conditions + T0R0) + 2 revisit)
    # synthetic paper v4 (2 x 13), KITTI paper v0 (2 x 13), top-view paper v0 (13), BEVPlace v0 (4)
    assert len(scored_every_query) == 26 + 26 + 13 + 4
    for name in tasks.SUITES:
        ids = tasks.suite(name)
        assert not set(ids) & set(superseded()), name
        for i in ids:
            spec = tasks.registry[i]
            assert spec.context_queries == (10 if spec.protocol != "revisit" else 0), i
    assert len(tasks.suite("all", source="synth")) == 29  # 26 paper, 2 revisit, the long drive
    assert tasks.suite("long") == ["SAFL/SynthL0-Revisit-v6"]
    assert set(tasks.suite("sanity", source="synth")) == {"SAFL/Synth00-T0R0-v6",
                                                          "SAFL/Synth09-T0R0-v6"}
    with pytest.warns(UserWarning, match="latest version SAFL/Synth00-T1R1-v6"):
        assert tasks.spec("SAFL/Synth00-T1R1").id == "SAFL/Synth00-T1R1-v6"
    with pytest.warns(UserWarning, match="superseded by SAFL/Synth00-T1R1-v6"):
        assert tasks.spec("SAFL/Synth00-T1R1-v4").data_version == "5"  # records resolve
    with pytest.warns(UserWarning, match="superseded by SAFL/Synth00-Revisit-v6"):
        assert tasks.spec("SAFL/Synth00-Revisit-v4").data_version == "5"  # and still run
    with pytest.warns(UserWarning, match="superseded by SAFL/Synth00-Revisit-v6"):
        assert tasks.spec("SAFL/Synth00-Revisit-v0").data_version == "1"  # records resolve
    with pytest.warns(UserWarning, match="superseded by SAFL/Synth00-Revisit-v6"):
        assert tasks.spec("SAFL/Synth00-Revisit-v1").data_version == "2"
    with pytest.warns(UserWarning, match="superseded by SAFL/Synth00-Revisit-v6"):
        assert tasks.spec("SAFL/Synth00-Revisit-v2").data_version == "3"
    with pytest.warns(UserWarning, match="superseded by SAFL/Synth00-Revisit-v6"):
        assert tasks.spec("SAFL/Synth00-Revisit-v3").data_version == "4"


def test_the_new_versions_differ_from_the_old_only_by_their_context_queries() -> None:
    """Successor and predecessor: the same definition but the context queries (so a record of
    the old version holds every outcome the new one scores), and no other pair."""
    from safl_bench.tasks.builtin import predecessor, successor

    pairs = {"SAFL/Synth00-T1R1-v4": "SAFL/Synth00-T1R1-v5",
             "SAFL/Synth09-T0R0-v4": "SAFL/Synth09-T0R0-v5",
             "SAFL/KITTI00-T20R2-v0": "SAFL/KITTI00-T20R2-v1",
             "SAFL/BEVKITTI00-T5R1.5-v0": "SAFL/BEVKITTI00-T5R1.5-v1",
             "SAFL/BEVKITTI02-BEVPlace-v0": "SAFL/BEVKITTI02-BEVPlace-v1"}
    for old, new in pairs.items():
        assert successor(old) == new and predecessor(new) == old
        a, b = tasks.registry[old].definition(), tasks.registry[new].definition()
        assert {k: v for k, v in b.items() if k != "context_queries"} == a
        assert b["context_queries"] == 10 and "context_queries" not in a
    for other in ("SAFL/Synth00-T1R1-v3", "SAFL/Synth00-T1R1-v5", "SAFL/Synth00-Revisit-v4",
                  "SAFL/BEVKITTI00-T1R1-v1",
                  "SAFL/BEVKITTI00-Revisit-v0", "nothing"):
        assert successor(other) is None
    assert predecessor("SAFL/Synth00-Revisit-v4") is None
    assert predecessor("SAFL/Synth00-T1R1-v6") is None  # other data, not a successor
    with pytest.raises(ConfigError, match="context_queries must be an integer >= 0"):
        TaskSpec(id="Test/A-v0", source="synth", sequence="00", context_queries=-1)


OLD_DATA = (r"^SAFL/Synth00-T1R1-v0 was defined on synthetic data version 1; this safl-bench "
            r"generates versions 5, 6: run SAFL/Synth00-T1R1-v6 ")
V1_DATA = (r"^SAFL/Synth00-T1R1-v1 was defined on synthetic data version 2; this safl-bench "
           r"generates versions 5, 6: run SAFL/Synth00-T1R1-v6 ")


def test_an_old_synthetic_task_cannot_be_materialised(tmp_path: Path) -> None:
    from safl_bench.sources import SynthSource
    from safl_bench.tasks.task import Task

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # fails before the "superseded" warning
        with pytest.raises(ConfigError, match=OLD_DATA):
            tasks.make("SAFL/Synth00-T1R1-v0")
        with pytest.raises(ConfigError, match=V1_DATA):
            tasks.make("SAFL/Synth00-T1R1-v1")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gymnasium's own "out of date" warning
        for old in ("v0", "v1", "v2", "v3"):
            with pytest.raises(ConfigError, match="run SAFL/Synth09-Revisit-v6"):
                gymnasium.make(f"SAFL/Synth09-Revisit-{old}").reset(seed=0)
    source = SynthSource(root=tmp_path, label="given", seed=0)
    with pytest.raises(ConfigError, match=OLD_DATA):  # whatever source it is given
        Task.from_spec(tasks.registry["SAFL/Synth00-T1R1-v0"], source=source)
    with pytest.raises(ConfigError, match=V1_DATA):
        Task.from_spec(tasks.registry["SAFL/Synth00-T1R1-v1"], source=source)


def test_an_old_synthetic_task_cannot_be_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from safl_bench import runner
    from safl_bench.method_registry import make_method

    assert cli_main(["run", "--method", "sad", "--task", "SAFL/Synth00-T1R1-v0",
                     "--results", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("safl-bench: error: SAFL/Synth00-T1R1-v0 was")
    assert "run SAFL/Synth00-T1R1-v6" in err[0]
    assert cli_main(["run", "--method", "sad", "--task", "SAFL/Synth00-T1R1-v1",
                     "--results", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("safl-bench: error: SAFL/Synth00-T1R1-v1 was")
    assert "run SAFL/Synth00-T1R1-v6" in err[0]
    with pytest.raises(ConfigError, match=OLD_DATA):
        runner.resolve_tasks(["SAFL/Synth00-T1R1-v0"])
    with pytest.raises(ConfigError, match=V1_DATA):
        runner.resolve_tasks(["SAFL/Synth00-T1R1-v1"])
    assert runner.resolve_tasks(["sanity"]) == ["SAFL/Synth00-T0R0-v6", "SAFL/Synth09-T0R0-v6"]
    options = runner.RunOptions(results_dir=tmp_path, progress=False)
    with pytest.raises(ConfigError, match=OLD_DATA):
        runner.run_cell(make_method("sad"), "SAFL/Synth00-T1R1-v0", options, log=print)
    with pytest.raises(ConfigError, match=V1_DATA):
        runner.run_cell(make_method("sad"), "SAFL/Synth00-T1R1-v1", options, log=print)
    with pytest.warns(UserWarning, match="superseded"):  # the failed cells' seeds are looked up
        outcomes = runner.run_grid([make_method("sad")], ["SAFL/Synth00-T1R1-v0", "SAFL/Synth00-T1R1-v1"],
                                   options, log=lambda _msg: None)
    assert [(o.task_id, o.seed) for o in outcomes] == [  # each of the tasks' five seeds fails
        (t, seed) for seed in range(5) for t in ("SAFL/Synth00-T1R1-v0", "SAFL/Synth00-T1R1-v1")]
    for outcome in outcomes:
        assert outcome.status == "failed" and "run SAFL/Synth00-T1R1-v6" in outcome.message
    assert not any(tmp_path.iterdir())  # nothing made, nothing written


def test_spec_validation() -> None:
    with pytest.raises(ConfigError, match="version"):
        TaskSpec(id="Test/NoVersion", source="synth", sequence="00")
    with pytest.raises(ConfigError, match="source"):
        TaskSpec(id="Test/A-v0", source="lidar", sequence="00")
    with pytest.raises(ConfigError, match="T0R0"):
        TaskSpec(
            id="Test/A-v0",
            source="synth",
            sequence="00",
            protocol="revisit",
            window_s=30.0,
            condition=Condition(1, 1),
            tp_radius_m=3,
            fp_radius_m=20,
        )
    with pytest.raises(ConfigError, match="time window"):
        TaskSpec(id="Test/A-v0", source="synth", sequence="00", window_s=30.0)
    with pytest.raises(ConfigError, match="step"):
        TaskSpec(id="Test/A-v0", source="synth", sequence="00", step=0)


def test_list_tasks_cli_shows_paper_and_revisit_tasks(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["list", "tasks"]) == 0
    out = capsys.readouterr().out
    for seq, source in (
        ("Synth00", "synthetic default"),
        ("KITTI00", "KITTI"),
        ("KITTI09", "KITTI"),
    ):
        for c in PAPER_CONDITIONS:
            for version, scored in ((5 if seq.startswith("Synth") else 1, "from query 10"),
                                    (2 if seq.startswith("Synth") else 0, "all queries")):
                line = next(x for x in out.splitlines()
                            if x.startswith(f"SAFL/{seq}-{c.name}-v{version} "))
                assert line.split()[1:4] == ["paper", seq[-2:], c.name]
                assert line.endswith(f"{source}  {scored}") or f"{source} " in line
                assert line.endswith(scored)
    assert "SAFL/KITTI08-Revisit-v0" in out and "SAFL/Synth00-Revisit-v6" in out
    assert (
        cli_main(["list", "tasks", "--suite", "paper", "--source", "kitti", "--fingerprints"]) == 0
    )
    lines = capsys.readouterr().out.splitlines()
    assert sum(line.startswith("SAFL/KITTI00-") for line in lines) == 12
    assert tasks.spec("SAFL/KITTI00-T1R1-v1").fingerprint in lines[2]


# ---------------------------------------------------------------- noise


@pytest.mark.parametrize("condition", [Condition(5.0, 1.5), Condition(20.0, 2.0)])
def test_viewpoint_noise_has_the_declared_distribution(condition: Condition) -> None:
    """Translation uniform over the disc of radius a (so r^2/a^2 ~ U(0,1), angle ~ U(0, 2 pi));
    heading uniform in (-b/2, b/2)."""
    off = sample_offsets(4000, condition, seed=7)
    a, b = condition.translation_m, condition.heading_rad
    r2 = (off[:, 0] ** 2 + off[:, 1] ** 2) / a**2
    angle = np.mod(np.arctan2(off[:, 1], off[:, 0]), 2 * np.pi) / (2 * np.pi)
    heading = off[:, 2] / b + 0.5
    for sample in (r2, angle, heading):
        assert stats.kstest(sample, "uniform").pvalue > 0.01
    assert np.abs(off[:, 2]).max() < b / 2 and r2.max() <= 1.0
    # a disc radius, not a square: a uniform square would give r^2/a^2 up to 2
    assert stats.kstest(np.sqrt(r2), "uniform").pvalue < 1e-6


# ---------------------------------------------------------------- materialised tasks


@pytest.fixture
def tiny_tasks(
    kitti_root: Path, safl_home: Path, temp_register: Callable[..., TaskSpec]
) -> Callable[..., tasks.TaskSpec]:
    """Register a paper task on the tiny KITTI-layout fixture (12 scans, every frame)."""

    def add(condition: str = "T1R1", seed: int = 0, version: int = 0) -> TaskSpec:
        return temp_register(
            f"Test/Tiny-{condition}-s{seed}-v{version}",
            source="kitti",
            sequence="00",
            condition=condition,
            step=1,
            seed=seed,
            map_config=TINY_MAP,
        )

    return add


def test_task_materialises_frames_positions_and_truth(
    kitti_root: Path, tiny_tasks: Callable[..., TaskSpec]
) -> None:
    spec = tiny_tasks("T1R1")
    task = tasks.make(spec.id, kitti_root=str(kitti_root), progress=False)
    assert len(task) == 12 and task.database_frames.tolist() == list(range(12))
    np.testing.assert_allclose(np.diff(task.database_times), 0.1, atol=1e-9)
    steps = np.hypot(*np.diff(task.database_positions, axis=0).T)
    np.testing.assert_allclose(steps, 1.0, atol=1e-6)  # the fixture drives 1 m per scan
    assert task.truth.labels(np.arange(12)).tolist() == [1] * 12
    assert task.truth.label_of(0, 9) == 1 and task.truth.distances(0, 9) <= 9.0
    assert task.truth.label_of(0, 11) == -1 and task.truth.distances(0, 11) > 10.0  # 11 m of road
    np.testing.assert_array_equal(task.query_offsets, sample_offsets(12, Condition(1, 1), 0))
    db, q = task.database("topview"), task.queries("topview")
    assert db.shape == q.shape == (12, 32, 32) and db.dtype == np.float32
    assert 0.0 <= db.min() and db.max() <= 1.0 and db.max() > 0
    assert not np.array_equal(db, q)  # the queries are re-rendered with noise
    points = task.database("points")
    assert len(points) == 12 and points[0].shape[1] == 3
    info = task.info()
    assert info["fingerprint"] == spec.fingerprint and info["data_label"] == "KITTI"
    with pytest.raises(ConfigError, match="view kind"):
        task.database("image")


def test_t0r0_queries_equal_the_database(
    kitti_root: Path, tiny_tasks: Callable[..., TaskSpec]
) -> None:
    task = tasks.make(tiny_tasks("T0R0").id, kitti_root=str(kitti_root), progress=False)
    db = task.database("topview")
    np.testing.assert_array_equal(task.queries("topview"), db)
    # and the noisy rendering path with zero offsets gives the clean maps too
    seq = task.source.sequence("00")
    zero = np.zeros((len(task.query_frames), 3))
    views = build_views(
        seq, TINY_MAP, task.query_frames, {"zero": zero}, ["topview"], progress=False
    )
    np.testing.assert_array_equal(views["zero", "topview"], db)


def test_same_seed_same_queries_other_seed_other_queries(
    kitti_root: Path,
    tiny_tasks: Callable[..., TaskSpec],
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
) -> None:
    first = tasks.make(tiny_tasks("T5R1", seed=3).id, kitti_root=str(kitti_root), progress=False)
    q1 = first.queries("topview")
    monkeypatch.setenv("SAFL_HOME", str(tmp_path / "fresh"))  # render again, not from the cache
    again = tasks.make(
        tiny_tasks("T5R1", seed=3, version=1).id, kitti_root=str(kitti_root), progress=False
    )
    np.testing.assert_array_equal(again.queries("topview"), q1)
    other = tasks.make(tiny_tasks("T5R1", seed=4).id, kitti_root=str(kitti_root), progress=False)
    assert not np.array_equal(other.queries("topview"), q1)
    np.testing.assert_array_equal(other.database("topview"), first.database("topview"))


def test_kitti_tasks_say_what_is_missing(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, kitti_root: Path
) -> None:
    monkeypatch.delenv("SAFL_KITTI_ROOT", raising=False)
    with pytest.raises(DataError, match=r"SAFL/KITTI00-T1R1-v1.*--kitti-root.*SAFL_KITTI_ROOT"):
        tasks.make("SAFL/KITTI00-T1R1-v1")
    with pytest.raises(DataError, match="does not exist"):
        tasks.make("SAFL/KITTI00-T1R1-v1", kitti_root=str(tmp_path / "nowhere"))
    monkeypatch.setenv("SAFL_KITTI_ROOT", str(kitti_root))
    with pytest.raises(DataError, match=r"SAFL/KITTI09-T1R1-v1.*09.*sequences under .*: 00"):
        tasks.make("SAFL/KITTI09-T1R1-v1")


def test_import_registers_tasks_without_loading_data() -> None:
    """`import safl_bench` registers every task with Gymnasium but builds nothing heavy."""
    code = (
        "import sys, safl_bench, gymnasium; "
        "assert 'SAFL/KITTI08-Revisit-v0' in gymnasium.registry; "
        "heavy = [m for m in ('torch', 'safl_bench.mapcache', 'safl_bench.tasks.task', 'pykitti') "
        "if m in sys.modules]; "
        "assert not heavy, heavy"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


def test_truth_at_viewpoint_measures_true_places_from_the_noisy_viewpoint(temp_register) -> None:
    """`Task.truth_for`: with truth_at=viewpoint a query's true places lie around the viewpoint
    its view was made at (its frame's pose moved by its offset in the robot frame); the default
    keeps the frames' poses; a task without headings says it cannot."""
    from safl_bench.matching.settings import EvaluationConfig
    from safl_bench.tasks.task import Task

    spec = temp_register("Test/TruthAt-T20R1-v0", source="synth", sequence="00", condition="T20R1",
                         map_config=TINY_MAP)
    n = 40
    positions = np.column_stack([np.arange(n) * 2.0, np.zeros(n)])  # a straight road along x
    headings = np.full(n, np.pi / 2)  # driving along +y in the robot frame's terms: x forward is world +y
    task = Task(spec, positions=positions, times=np.arange(n) * 0.1, headings=headings)
    assert task.truth_for(EvaluationConfig()) is task.truth
    moved = task.truth_for(EvaluationConfig(truth_at="viewpoint"))
    dx, dy = task.query_offsets[:, 0], task.query_offsets[:, 1]
    expected = task.query_positions + np.column_stack([-dy, dx])  # rotated by +90 degrees
    np.testing.assert_allclose(moved.query_positions, expected, atol=1e-9)
    np.testing.assert_array_equal(moved.database_positions, task.truth.database_positions)
    assert not np.allclose(moved.query_positions, task.query_positions)
    bare = Task(spec, positions=positions, times=np.arange(n) * 0.1)
    with pytest.raises(ConfigError, match="truth_at=viewpoint needs the frames' headings"):
        bare.truth_for(EvaluationConfig(truth_at="viewpoint"))


def test_a_task_id_without_its_namespace_is_refused_with_the_full_id_suggested(
        capsys: pytest.CaptureFixture[str]) -> None:
    from safl_bench.run.runner import resolve_tasks

    with pytest.raises(RegistryError, match=r"unknown task or suite 'BEVKITTI00-BEVPlace-RotQueries-v1'"
                       r".* Did you mean: SAFL/BEVKITTI00-BEVPlace-RotQueries-v1\?$"):
        resolve_tasks(["BEVKITTI00-BEVPlace-RotQueries-v1"])
    with pytest.raises(RegistryError, match=r"Did you mean: SAFL/Synth00-Revisit-v4"):
        resolve_tasks(["Synth00-Revisit-v4"])
    with pytest.raises(RegistryError, match=r"Did you mean: SAFL/KITTI00-T5R1\.5-v"):
        tasks.suite("KITI00-T5R1.5-v1")  # a close match of one
    with pytest.raises(RegistryError, match=r"^unknown suite 'papr'.*Did you mean: paper\?$"):
        tasks.suite("papr")
    assert cli_main(["run", "--method", "sad", "--task", "Synth09-T1R1-v5", "--results", "unused"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith("Did you mean: SAFL/Synth09-T1R1-v5?")


def test_an_old_task_version_is_warned_about_once() -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(9):
            tasks.spec("SAFL/Synth00-T1R1-v4")
    assert [str(w.message) for w in caught] == [
        "task SAFL/Synth00-T1R1-v4 is superseded by SAFL/Synth00-T1R1-v6"]
