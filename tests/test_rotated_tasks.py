"""Top-view tasks on a second, rotated image folder of the same sequences (BEVPlace's KITTIRot):
queries from it and the database from the plain images, or both from it; the two folders must
hold the same frames (bad input: one line naming both counts or the first differing pose line)."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from conftest import write_bev

from safl_bench import tasks
from safl_bench.cli import main as cli_main
from safl_bench.errors import ConfigError, DataError
from safl_bench.leaderboard.site import explain_command
from safl_bench.results.records import load_record, rerun_command
from safl_bench.sources import bev_source
from safl_bench.tasks.builtin import REVISIT_SEQUENCES, rotated_id

QUERIES = "Test/BevTiny-BEVPlace-RotQueries-v0"
BOTH = "Test/BevTinyRot-BEVPlace-v0"
REVISIT = "Test/BevTiny-Revisit-RotQueries-v0"


@pytest.fixture
def roots(tmp_path: Path) -> tuple[Path, Path]:
    """A plain folder and a "rotated" one: other images (another pattern), the same 40 poses."""
    return write_bev(tmp_path / "plain"), write_bev(tmp_path / "rot", seed=1)


@pytest.fixture
def rotated_tasks():
    ranges = dict(source="bev", sequence="00", protocol="bevplace", step=1, database_frames=(0, 20),
                  query_frames=(20, 40), tp_radius_m=5.0, fp_radius_m=5.0)
    specs = [tasks.register(QUERIES, rotated="queries", **ranges),
             tasks.register(BOTH, rotated="both", **ranges),
             tasks.register(REVISIT, source="bev", sequence="00", protocol="revisit", step=1,
                            tp_radius_m=3.0, fp_radius_m=20.0, window_s=5.0, rotated="queries")]
    yield
    for s in specs:
        tasks.unregister(s.id)


def _images(root: Path, frames: np.ndarray) -> np.ndarray:
    return bev_source(root).images("00", progress=False)[frames].astype(np.float32) / 255


def test_queries_come_from_the_second_folder_and_the_database_from_the_first(
        roots, safl_home, rotated_tasks) -> None:
    plain, rot = roots
    task = tasks.make(QUERIES, bev_root=str(plain), bev_rot_root=str(rot), progress=False)
    np.testing.assert_array_equal(task.database(), _images(plain, task.database_frames))
    np.testing.assert_array_equal(task.queries(), _images(rot, task.query_frames))
    info = task.info()
    assert info["rotated"] == "queries"
    assert [n.split(" ")[0] for n in info["data_notes"]] == ["database", "queries"]
    assert str(rot / "00" / "imgs") in info["data_notes"][1]

    both = tasks.make(BOTH, bev_rot_root=str(rot), progress=False)  # needs no plain folder
    np.testing.assert_array_equal(both.database(), _images(rot, both.database_frames))
    np.testing.assert_array_equal(both.queries(), _images(rot, both.query_frames))

    revisit = tasks.make(REVISIT, bev_root=str(plain), bev_rot_root=str(rot), progress=False)
    assert not revisit.shared_views  # same frames, other images
    np.testing.assert_array_equal(revisit.queries(), _images(rot, revisit.query_frames))
    np.testing.assert_array_equal(revisit.database(), _images(plain, revisit.database_frames))


def test_the_second_root_comes_from_the_environment_too(roots, safl_home, rotated_tasks,
                                                        monkeypatch) -> None:
    plain, rot = roots
    monkeypatch.setenv("SAFL_BEV_ROT_ROOT", str(rot))
    env = gymnasium.make(QUERIES, bev_root=str(plain), progress=False)
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(obs, _images(rot, np.array([20]))[0])
    env.close()


def test_without_the_second_root_one_line_names_its_option(roots, rotated_tasks, monkeypatch) -> None:
    monkeypatch.delenv("SAFL_BEV_ROT_ROOT", raising=False)
    for task_id in (QUERIES, BOTH):
        with pytest.raises(DataError, match=rf"^task {task_id} needs the rotated top-view images "
                                            r".*: pass --bev-rot-root DIR or set SAFL_BEV_ROT_ROOT$"):
            tasks.make(task_id, bev_root=str(roots[0]))
    with pytest.raises(DataError, match="are the same folder"):
        tasks.make(QUERIES, bev_root=str(roots[0]), bev_rot_root=str(roots[0]))


def test_a_second_folder_with_other_frames_is_one_line_naming_both_counts(
        tmp_path, rotated_tasks) -> None:
    plain, rot = write_bev(tmp_path / "plain"), write_bev(tmp_path / "rot", n=38)
    with pytest.raises(DataError) as err:
        tasks.make(QUERIES, bev_root=str(plain), bev_rot_root=str(rot))
    message = str(err.value)
    assert message == (f"task {QUERIES}: {rot / '00' / 'imgs'} has 38 images but "
                       f"{plain / '00' / 'imgs'} has 40: the two image folders of sequence 00 must "
                       "hold the same frames")


def test_a_second_folder_with_other_poses_is_one_line_naming_the_first_differing_line(
        roots, rotated_tasks, safl_home, capsys) -> None:
    plain, rot = roots
    lines = (rot / "00" / "pose.txt").read_text().splitlines()
    for i in (6, 30):  # frames 6 and 30 moved: line 7 is the first that differs
        values = [float(v) for v in lines[i].split()]
        values[3] += 0.5
        lines[i] = " ".join(f"{v:.9e}" for v in values)
    (rot / "00" / "pose.txt").write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=rf"^task {QUERIES}: {rot / '00' / 'pose.txt'} line 7 differs "
                                        rf"from {plain / '00' / 'pose.txt'} line 7 \(by 0\.5\)"):
        tasks.make(QUERIES, bev_root=str(plain), bev_rot_root=str(rot))
    code = cli_main(["run", "--method", "sad", "--quiet", "--results", str(safl_home / "r"),
                     "--bev-root", str(plain), "--bev-rot-root", str(rot), "--task", QUERIES])
    err = capsys.readouterr().err
    assert code == 2 and "line 7 differs" in err and "Traceback" not in err
    same = (plain / "00" / "pose.txt").read_text().splitlines()
    values = [float(v) for v in same[6].split()]
    values[3] += 1e-9  # within the tolerance: the same frame
    lines[6], lines[30] = " ".join(f"{v:.12e}" for v in values), same[30]
    (rot / "00" / "pose.txt").write_text("\n".join(lines) + "\n")
    tasks.make(QUERIES, bev_root=str(plain), bev_rot_root=str(rot))


def test_a_run_records_the_rotated_label_and_both_folders(roots, safl_home, tmp_path,
                                                         rotated_tasks) -> None:
    plain, rot = roots
    results = tmp_path / "results"
    code = cli_main(["run", "--method", "sad", "--quiet", "--results", str(results), "--bev-root",
                     str(plain), "--bev-rot-root", str(rot), "--task", QUERIES, "--task", BOTH])
    assert code == 0
    labels, commands = {}, {}
    for path in results.rglob("seed-0.json"):
        record = json.loads(path.read_text())
        labels[record["task"]["id"]] = record["task"]["source_label"]
        assert record["task"]["spec"]["rotated"] in ("queries", "both")
        loaded = load_record(path)
        commands[loaded.task.id] = (rerun_command(loaded), explain_command(loaded, "r"))
    assert commands[QUERIES][0].endswith(" --bev-root DIR --bev-rot-root DIR --force")
    assert commands[BOTH][0].endswith(f"--task {BOTH} --seed 0 --bev-rot-root DIR --force")
    assert commands[QUERIES][1].endswith(" --bev-root DIR --bev-rot-root DIR")
    assert labels == {QUERIES: "KITTI top-view images, rotated queries (KITTIRot)",
                      BOTH: "KITTI top-view images, rotated database and queries (KITTIRot)"}


def test_rotated_is_for_image_tasks_only() -> None:
    with pytest.raises(ConfigError, match="belongs to top-view image tasks"):
        tasks.TaskSpec(id="Test/X-v0", source="synth", sequence="00", rotated="queries")
    with pytest.raises(ConfigError, match="rotated is one of queries, both"):
        tasks.TaskSpec(id="Test/X-v0", source="bev", sequence="00", rotated="yes")


def test_the_builtin_rotated_tasks_copy_the_plain_ones() -> None:
    for sequence in REVISIT_SEQUENCES["bev"]:
        for protocol, plain_id in (("bevplace", f"SAFL/BEVKITTI{sequence}-BEVPlace-v1"),
                                   ("revisit", f"SAFL/BEVKITTI{sequence}-Revisit-v0")):
            plain = tasks.spec(plain_id)
            kinds = ("queries", "both") if protocol == "bevplace" else ("queries",)
            for rotated in kinds:
                task = tasks.spec(rotated_id(sequence, protocol, rotated))
                assert task.rotated == rotated
                assert task.definition() == {**plain.definition(), "rotated": rotated}
                assert task.id in tasks.suite("bev-rotated") and task.id in tasks.suite("all")
                assert task.id not in tasks.suite("bev-bevplace") + tasks.suite("bev-revisit")
    assert tasks.spec("SAFL/BEVKITTIRot02-BEVPlace-v1").context_queries == 10
    assert len(tasks.suite("bev-rotated")) == 12


def test_the_leaderboard_tables_each_reading_of_the_images_apart(tmp_path) -> None:
    from record_factory import make_record

    from safl_bench.leaderboard import build_leaderboard
    from safl_bench.leaderboard.guides import bevplace_reproduction
    from safl_bench.sources.bev import BEV_LABEL, ROTATED_LABELS

    records = [make_record(method, protocol="bevplace", condition=None, sequence=s, source_kind="bev",
                           task_version=1, source_label=label, recall_at_1=r)
               for label, r in ((ROTATED_LABELS["both"], 0.5), (BEV_LABEL, 0.9),
                                (ROTATED_LABELS["queries"], 0.3))
               for s in ("00", "05") for method in ("bevplace", "sad")]
    report = build_leaderboard(records, tmp_path / "lb", figures=False)
    index = (tmp_path / "lb" / "index.md").read_text()
    for label in (BEV_LABEL, *ROTATED_LABELS.values()):
        assert f"## {label}\n" in index
    block = bevplace_reproduction(report)
    assert block is not None
    readings = block.split("\n\n**")
    assert len(readings) == 3 and readings[0].startswith(f"**{BEV_LABEL}**: BEVPlace's protocol")
    assert [r.split("**")[0] for r in readings[1:]] == sorted(ROTATED_LABELS.values())
    for reading in readings:  # each beside the published figures, 05's too
        assert "| BEVPlace (published) | — | 99.7 | — | 99.3 | — |" in reading
