"""Result records: round trip, atomic writes, validation of corrupt files, loading a directory."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from record_factory import make_record

from safl_bench.errors import DataError
from safl_bench.provenance import collect_environment
from safl_bench.records import (
    MAX_CURVE_POINTS,
    CorruptRecordError,
    ResultRecord,
    downsample_curve,
    find_record,
    load_existing,
    load_record,
    load_records,
    record_path,
    write_record,
)


def test_round_trip_through_file(tmp_path: Path) -> None:
    record = make_record("stable_afl", condition="T5R1.5", seed=3)
    path = write_record(tmp_path, record)
    assert path == tmp_path / "stable_afl@1" / "SAFL__Synth00-T5R1.5-v0" / "seed-3.json"
    assert load_record(path) == record
    assert ResultRecord.from_json(json.loads(json.dumps(record.to_json()))) == record
    assert find_record(tmp_path, "stable_afl", "1", record.task.id, 3) == path
    assert find_record(tmp_path, "stable_afl", "1", record.task.id, 4) is None
    assert load_existing(tmp_path, "stable_afl", "1", record.task.id, 3) == record


def test_file_is_reproducible_and_small(tmp_path: Path) -> None:
    record = make_record()
    first = write_record(tmp_path / "a", record).read_bytes()
    second = write_record(tmp_path / "b", record).read_bytes()
    assert first == second
    data = json.loads(first)
    assert set(data["results"]) == {"sequence", "single_frame"}
    assert set(data["results"]["sequence"]["curves"]) == {"pr", "roc"}
    assert len(first) < 20_000


def test_write_is_atomic_and_leaves_no_temp_files(tmp_path: Path) -> None:
    path = write_record(tmp_path, make_record())
    write_record(tmp_path, make_record(recall=0.25))  # overwrite in place
    assert [p.name for p in path.parent.iterdir()] == ["seed-0.json"]
    assert load_record(path).results["sequence"].metrics.recall_at_100_precision == 0.25
    good = make_record()
    seq = good.results["sequence"]
    nan_metrics = dataclasses.replace(seq.metrics, auc=float("nan"))
    bad = dataclasses.replace(
        good, results={**good.results, "sequence": dataclasses.replace(seq, metrics=nan_metrics)}
    )
    with pytest.raises(CorruptRecordError, match="auc"):
        write_record(tmp_path / "bad", bad)
    assert not any((tmp_path / "bad").rglob("*.*")), "a refused record must leave no file behind"


def test_records_get_the_permissions_of_an_ordinary_write(tmp_path: Path) -> None:
    """0666 less the umask (a group or CI job can read a shared results folder), not the
    temporary file's 0600."""
    import os
    import stat

    old = os.umask(0o022)
    try:
        path = write_record(tmp_path, make_record())
        assert stat.S_IMODE(path.stat().st_mode) == 0o644
        os.umask(0o002)
        write_record(tmp_path, make_record(recall=0.25))
        assert stat.S_IMODE(path.stat().st_mode) == 0o664
    finally:
        os.umask(old)


def test_curves_are_downsampled() -> None:
    x = np.linspace(0, 1, 5000)
    xs, ys = downsample_curve(x, x**2)
    assert len(xs) == len(ys) <= MAX_CURVE_POINTS
    assert xs[0] == 0.0 and xs[-1] == 1.0 and ys[-1] == 1.0
    assert downsample_curve([0.0, 1.0], [1.0, 0.0]) == ([0.0, 1.0], [1.0, 0.0])


def _corrupt(tmp_path: Path, edit) -> Path:
    path = write_record(tmp_path, make_record())
    data = json.loads(path.read_text())
    text = edit(data)
    path.write_text(text if isinstance(text, str) else json.dumps(data))
    return path


@pytest.mark.parametrize(
    ("edit", "reason"),
    [
        (lambda d: json.dumps(d)[:300], "not valid JSON"),
        (
            lambda d: d["results"]["sequence"]["metrics"].pop("auc"),
            r"results\.sequence\.metrics\.auc: missing",
        ),
        (lambda d: d.pop("timings"), "timings: missing"),
        (lambda d: d["task"].update(version="0"), r"task\.version: expected an integer"),
        (lambda d: d["task"].update(protocol="other"), r"task\.protocol: must be one of"),
        (lambda d: d["results"]["sequence"]["metrics"].update(f1_max=1.5), "fraction"),
        (lambda d: d["results"].update(bogus={}), "unknown matching mode"),
        (lambda d: d.update(schema=99), "schema"),
        (lambda d: d["results"]["sequence"]["curves"]["pr"]["recall"].pop(), "differ in length"),
        (lambda d: json.dumps(d).replace('"matcher_s": 1.5', '"matcher_s": NaN'), "not valid JSON"),
        (lambda d: d.update(created="yesterday"), "ISO 8601"),
    ],
)
def test_corrupt_record_is_reported_by_file(tmp_path: Path, edit, reason: str) -> None:
    path = _corrupt(tmp_path, edit)
    with pytest.raises(CorruptRecordError, match=reason) as info:
        load_record(path)
    assert str(path) in str(info.value)
    assert isinstance(info.value, DataError)
    assert info.value.path == path


def test_load_records_skips_and_reports_corrupt_files(tmp_path: Path) -> None:
    good = [make_record("a", seed=s) for s in (0, 1)] + [make_record("b")]
    for record in good:
        write_record(tmp_path, record)
    broken = record_path(tmp_path, "a", "1", good[0].task.id, 0)
    broken.write_text(broken.read_text()[:-40])  # truncated
    (broken.parent / ".seed-0.abc.tmp.json").write_text("{")  # interrupted write: ignored
    records, problems = load_records(tmp_path)
    assert {(r.method.name, r.seed) for r in records} == {("a", 1), ("b", 0)}
    assert [p.path for p in problems] == [broken]
    assert "not valid JSON" in problems[0].reason
    assert load_records(tmp_path / "missing") == ([], [])


def test_load_existing_rejects_a_record_of_another_run(tmp_path: Path) -> None:
    record = make_record("a", seed=0)
    path = write_record(tmp_path, record)
    other = record_path(tmp_path, "a", "1", record.task.id, 1)
    other.write_bytes(path.read_bytes())  # copied to the wrong seed
    with pytest.raises(CorruptRecordError, match=r"seed-1\.json"):
        load_existing(tmp_path, "a", "1", record.task.id, 1)


def test_task_ids_map_to_safe_paths(tmp_path: Path) -> None:
    path = record_path(tmp_path, "my method", "0.2", "SAFL/KITTI00-T1R1-v0", 0)
    assert path.relative_to(tmp_path).parts == (
        "my_method@0.2",
        "SAFL__KITTI00-T1R1-v0",
        "seed-0.json",
    )


def test_environment_is_collected() -> None:
    env = collect_environment()
    assert env.python.count(".") == 2
    assert env.cpu_cores >= 1 and env.cpu_model
    assert env.libraries["numpy"] == np.__version__
    assert env.git_revision


def test_records_built_from_a_task_spec_and_an_evaluation(tmp_path: Path) -> None:
    from safl_bench.matching import MatcherConfig
    from safl_bench.metrics import evaluate
    from safl_bench.records import MethodInfo, mode_result_from_evaluation, new_record, task_info
    from safl_bench.tasks import spec

    rng = np.random.default_rng(0)
    evaluation = evaluate(rng.random(500), rng.random(500) < 0.6, np.ones(500, bool))
    result = mode_result_from_evaluation(evaluation)
    assert result.metrics.auc == pytest.approx(evaluation.roc_auc)
    assert result.metrics.n_positives == 500
    assert len(result.curves.pr.recall) <= MAX_CURVE_POINTS
    paper = task_info(spec("SAFL/Synth00-T1R1-v4"), "synthetic default (seed 0)", data="abc")
    assert (paper.protocol, paper.condition, paper.version) == ("paper", "T1R1", 4)
    assert paper.spec["data_version"] == "5"
    assert paper.spec["data"] == "abc" and paper.spec_fingerprint == paper.spec["fingerprint"]
    revisit = task_info(spec("SAFL/Synth00-Revisit-v4"), "synthetic default (seed 0)")
    assert revisit.condition is None and revisit.protocol == "revisit"
    record = new_record(
        method=MethodInfo("sad", "1", {"size": 32}),
        task=paper,
        seed=0,
        matcher=MatcherConfig(),
        results={"sequence": result, "single_frame": result},
        timings=make_record().timings,
    )
    assert record.matcher["ds"] == 10 and record.created.endswith("Z")
    assert load_record(write_record(tmp_path, record)) == record


def test_version_1_records_are_kept_only_where_version_2_scores_the_same(tmp_path: Path) -> None:
    import json

    from record_factory import make_record

    from safl_bench.records import load_records, write_record

    paper = write_record(tmp_path, make_record("a"))
    revisit = write_record(tmp_path, make_record("b", protocol="revisit", condition=None))
    for path, spec in ((paper, {"tp_radius_m": 10.0, "fp_radius_m": 10.0, "window_s": None}),
                       (revisit, {"tp_radius_m": 3.0, "fp_radius_m": 20.0, "window_s": 30.0})):
        data = json.loads(path.read_text())
        data.pop("metrics_version")
        data["task"]["spec"].update(spec)
        path.write_text(json.dumps(data))
    records, problems = load_records(tmp_path)
    assert [r.method.name for r in records] == ["a"] and records[0].metrics_version == 1
    assert len(problems) == 1 and problems[0].path == revisit
    assert "metrics version 1" in problems[0].reason and "safl-bench run --method b@1" in problems[0].reason


REPO = Path(__file__).resolve().parents[1]


def test_the_published_record_schema_is_current() -> None:
    from safl_bench.cli.records_schema import schema_text

    committed = (REPO / "docs" / "reference" / "record.schema.json").read_text(encoding="utf-8")
    assert committed == schema_text(), "regenerate: safl-bench records schema --out docs/reference/record.schema.json"


def test_the_schema_states_the_rules_of_the_fields() -> None:
    from safl_bench.results.records import record_schema

    schema = record_schema()
    assert {"method", "task", "seed", "results", "timings", "environment", "created", "schema"} <= set(
        schema["required"])
    task = schema["$defs"]["TaskInfo"]["properties"]
    assert task["protocol"]["enum"] == ["paper", "revisit", "bevplace"]
    f1 = schema["$defs"]["Metrics"]["properties"]["f1_max"]["anyOf"][0]
    assert (f1["minimum"], f1["maximum"]) == (0, 1)


def test_every_file_the_schema_accepts_is_a_record_and_a_bad_one_fails_it(tmp_path: Path) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    from safl_bench.results.records import record_schema

    path = write_record(tmp_path, make_record())
    data = json.loads(path.read_text())
    jsonschema.validate(data, record_schema())
    data["task"]["protocol"] = "other"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(data, record_schema())


def test_records_check_names_the_file_and_field_and_exits_2(tmp_path: Path, capsys) -> None:
    from safl_bench.cli import main as cli_main

    good = write_record(tmp_path, make_record("a"))
    bad = write_record(tmp_path, make_record("b"))
    data = json.loads(bad.read_text())
    data["timings"]["repeats"] = "five"
    bad.write_text(json.dumps(data))
    assert cli_main(["records", "check", str(tmp_path)]) == 2
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if str(bad) in line]
    assert len(lines) == 1 and "timings.repeats: expected an integer, got str" in lines[0]
    assert str(good) not in captured.err and "1 valid records" in captured.out
    records, problems = load_records(tmp_path)
    assert [r.method.name for r in records] == ["a"] and problems[0].corrupt
