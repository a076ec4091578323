"""Method versions (issue 26): several versions of one name are registered side by side, a bare
name is the newest, `name@V` selects one; records, weights and tables keep versions apart."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from record_factory import make_record, scored_record

from safl_bench.cli import main
from safl_bench.errors import ConfigError, DataError, RegistryError
from safl_bench.methods import method as reg
from safl_bench.methods.method import Method

NAME = "test_versioned"

#: A trainable method at several versions, written as a module file with a `weights/` folder
#: beside it: where `shipped_weights_path` looks.
MODULE = '''
import numpy as np
import torch

from safl_bench.methods.method import Method


class Base(Method):
    """A versioned test method: its descriptor is the maps' mean times a learned scale."""

    name = "test_versioned"
    trainable = True

    def __init__(self, seed: int = 0):
        self.seed = seed
        self.scale = torch.ones(1)

    def describe(self, maps):
        return (np.asarray(maps).reshape(len(maps), -1).mean(axis=1, keepdims=True)
                * float(self.scale)).astype(np.float32)

    def state_tensors(self, parts=None):
        return {"scale": self.scale}

    def load_state_tensors(self, tensors, *, source):
        self.scale = tensors["scale"]


def version(v):
    return type(f"V{v.replace('.', '_')}", (Base,), {"version": v, "__module__": __name__})


V1, V2, V9, V10 = (version(v) for v in ("1", "2", "9", "10"))
'''


@pytest.fixture
def versions(tmp_path: Path) -> Iterator[ModuleType]:
    """The module above, imported from tmp_path/pkg, with versions 1, 2, 9 and 10 registered."""
    folder = tmp_path / "pkg"
    (folder / "weights").mkdir(parents=True)
    (folder / "versioned_mod.py").write_text(MODULE)
    spec = importlib.util.spec_from_file_location("test_versioned_mod", folder / "versioned_mod.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    for cls in (module.V2, module.V10, module.V1, module.V9):  # in no order
        reg.register_method(cls)
    try:
        yield module
    finally:
        if reg.method_versions(NAME):
            reg.unregister_method(NAME)
        del sys.modules[spec.name]


def test_a_bare_name_is_the_newest_version_and_name_at_v_selects_one(versions: ModuleType) -> None:
    assert reg.method_versions(NAME) == ["1", "2", "9", "10"]  # "10" after "9"
    assert reg.method_class(NAME) is versions.V10
    assert reg.method_class(f"{NAME}@1") is versions.V1
    assert reg.method_class(f"{NAME}@9") is versions.V9
    assert isinstance(reg.make_method(f"{NAME}@2", weights="untrained"), versions.V2)
    assert [i.version for i in reg.list_methods(all_versions=True) if i.name == NAME] == ["1", "2", "9", "10"]
    assert [i.version for i in reg.list_methods() if i.name == NAME] == ["10"]
    assert reg.method_selector(NAME, "10") == NAME and reg.method_selector(NAME, "2") == f"{NAME}@2"


def test_version_order_is_numeric_part_by_part() -> None:
    ordered = ["1", "1.2", "1.10", "2", "9", "10", "10.rc"]
    assert sorted(reversed(ordered), key=reg.version_key) == ordered
    assert reg.version_key("10") > reg.version_key("9")


def test_an_unknown_version_is_one_line_listing_the_registered_ones(versions: ModuleType, capsys) -> None:
    with pytest.raises(RegistryError, match=rf"no version '3'.*registered: {NAME}@1, {NAME}@2, {NAME}@9, {NAME}@10"):
        reg.method_class(f"{NAME}@3")
    assert main(["run", "--method", "stable_afl@7", "--quiet"]) == 2  # before any work
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "stable_afl@1, stable_afl@2" in err[0]


def test_unregistering_one_version_keeps_the_others(versions: ModuleType) -> None:
    reg.unregister_method(f"{NAME}@10")
    assert reg.method_class(NAME) is versions.V9  # the newest left
    with pytest.raises(RegistryError, match="no method"):
        reg.unregister_method(f"{NAME}@10")
    for v in ("1", "2", "9"):
        reg.unregister_method(f"{NAME}@{v}")
    with pytest.raises(RegistryError, match="unknown method"):
        reg.method_class(NAME)


def test_a_version_is_registered_once(versions: ModuleType) -> None:
    other = type("Other", (versions.Base,), {"version": "2"})
    with pytest.raises(RegistryError, match="version '2' is taken"):
        reg.register_method(other)


def test_load_picks_the_class_of_the_saved_version(versions: ModuleType, tmp_path: Path) -> None:
    path = versions.V1(seed=4).save(tmp_path / "w.safetensors")
    loaded = Method.load(path)
    assert type(loaded) is versions.V1 and loaded.seed == 4 and loaded.weights_info["saved_version"] == "1"
    assert isinstance(reg.make_method(f"{NAME}@1", weights=str(path)), versions.V1)
    # a bare name runs the version of the file given; an explicit other version is an error
    assert isinstance(reg.make_method(NAME, weights=str(path)), versions.V1)
    with pytest.raises(DataError, match=rf"weights of {NAME}@1, not of {NAME}@10; .*--method {NAME}@1"):
        reg.make_method(f"{NAME}@10", weights=str(path))
    with pytest.raises(DataError, match="not of"):
        versions.V2.load(path)


def test_shipped_weights_are_per_version(versions: ModuleType) -> None:
    folder = Path(versions.__file__).parent / "weights"
    assert reg.shipped_weights_path(versions.V1) is None  # ships none yet
    legacy = versions.V1().save(folder / f"{NAME}.safetensors")  # a first release's file: version 1 inside
    assert reg.shipped_weights_path(versions.V1) == legacy
    assert reg.shipped_weights_path(versions.V2) is None  # never another version's weights
    v2 = versions.V2().save(folder / f"{NAME}-v2.safetensors")
    v2_bev = versions.V2().save(folder / f"{NAME}-v2-bev.safetensors")
    assert reg.shipped_weights_path(versions.V2) == v2
    assert reg.shipped_weights_path(versions.V2, "bev") == v2_bev
    assert reg.shipped_weights_path(versions.V2, "kitti") == v2  # no KITTI weights: the default's
    assert reg.shipped_weights_path(versions.V1, "bev") == legacy
    (folder / f"{NAME}-bev.safetensors").write_bytes(b"not safetensors")  # unreadable legacy file
    assert reg.shipped_weights_path(versions.V1, "bev") == legacy
    shipped = reg.make_method(f"{NAME}@2", source="bev")
    assert shipped.weights_info["path"].endswith(f"weights/{NAME}-v2-bev.safetensors")
    with pytest.raises(ConfigError, match=rf"{NAME}@9 has no weights for the synthetic default; "
                       rf"versions with weights for it: {NAME}@1, {NAME}@2 .*"
                       rf"`safl-bench train --method {NAME}@9`"):
        reg.make_method(f"{NAME}@9")  # never the untrained networks unless asked


def test_list_methods_shows_every_version_and_its_weights(versions: ModuleType, capsys) -> None:
    folder = Path(versions.__file__).parent / "weights"
    versions.V1().save(folder / f"{NAME}.safetensors")
    versions.V2().save(folder / f"{NAME}-v2-bev.safetensors")
    assert main(["list", "methods", "--json"]) == 0
    rows = {(r["name"], r["version"]): r for r in json.loads(capsys.readouterr().out)}
    mine = {v: rows[(NAME, v)] for v in ("1", "2", "9", "10")}
    assert [v for v, r in mine.items() if r["bare_name"]] == ["10"]
    # a bare name runs 1 on the synthetic default and KITTI scans (its weights), 2 on top views
    assert mine["1"]["select"] == f"{NAME}@1 ({NAME} on synth, kitti)"
    assert mine["2"]["select"] == f"{NAME}@2 ({NAME} on bev)" and mine["10"]["select"] == f"{NAME}@10"
    assert mine["1"]["bare_name_runs_on"] == ["synth", "kitti"] and mine["10"]["bare_name_runs_on"] == []
    assert mine["1"]["weights"] == {"synth": f"{NAME}.safetensors"}
    assert mine["2"]["weights"] == {"bev": f"{NAME}-v2-bev.safetensors"}
    assert mine["9"]["weights"] == {}
    assert rows[("sad", "1")]["weights"] is None and rows[("sad", "1")]["select"] == "sad"
    assert main(["list", "methods"]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.startswith(NAME) and f"{NAME}@2 " in ln)
    assert "bev" in line and "synth" not in line
    assert "A bare name runs, on each data source, the newest version with weights for it" in out


def test_the_run_table_keeps_two_versions_of_a_name_apart() -> None:
    from safl_bench.run import runner

    outcomes = [runner.CellOutcome(r.task.id, r.seed, "computed", Path("x"), r, method=r.method.name,
                                   version=r.method.version)
                for v, skill in (("1", 0.9), ("2", 0.3)) for s in (0, 1)
                for r in [scored_record("stable_afl", seed=s, skill=skill, method_version=v)]]
    lines = runner.summary_table(outcomes).splitlines()
    assert lines[0].split()[:2] == ["method", "task"]
    rows = [ln.split(maxsplit=1) for ln in lines[2:4]]
    assert [r[0] for r in rows] == ["stable_afl@1", "stable_afl@2"]
    assert rows[0][1] != rows[1][1]  # each version its own figures, never a mean of both
    assert len(lines[4:]) == len(runner.summary_table(outcomes[:2]).splitlines()[3:])  # no third row
    one = runner.summary_table(outcomes[:2]).splitlines()
    assert one[0].split()[0] == "task"  # one version: no method column, as before


def test_the_leaderboard_keeps_two_versions_of_a_name_apart() -> None:
    from safl_bench.leaderboard.grouping import table_key
    from safl_bench.leaderboard.site import explain_command
    from safl_bench.leaderboard.tables import recall_table

    records = [make_record("stable_afl", method_version=v, condition=c, recall=r, seed=s)
               for v, r in (("1", 0.9), ("2", 0.2)) for c in ("T1R1", "T5R1") for s in (0, 1)]
    table = recall_table(table_key(records[0]), records)
    assert table.rows == [("stable_afl", "1", "sequence"), ("stable_afl", "1", "single-frame"),
                          ("stable_afl", "2", "sequence"), ("stable_afl", "2", "single-frame")]
    assert [table.cells[i][0].mean for i in (0, 2)] == [pytest.approx(0.9), pytest.approx(0.2)]
    assert "| stable_afl | 2 | sequence |" in table.markdown()
    # each record's explain command selects its own version (a bare name runs, on the synthetic
    # default, the newest version with weights for it: 1, so a record of 2 names its version)
    assert "--method stable_afl@1 " in explain_command(records[0], "r")
    assert "--method stable_afl@2 " in explain_command(records[-1], "r")


def test_compare_reads_one_version_a_bare_name_the_one_run_runs(tmp_path: Path, capsys) -> None:
    from safl_bench.records import write_record

    for v, skill in (("1", 0.9), ("2", 0.3)):
        for seed in (0, 1):
            write_record(tmp_path, scored_record("stable_afl", seed=seed, skill=skill, method_version=v))
    # on the synthetic default a bare name runs version 1 (the newest with weights there)
    argv = ["compare", "--method", "stable_afl@2", "--method", "stable_afl", "--results", str(tmp_path)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "A = stable_afl@2, B = stable_afl" in out and "verdict: B better on" in out
    assert main(["compare", "--method", "stable_afl@3", "--method", "stable_afl", "--results",
                 str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "no records of stable_afl@3; records of stable_afl@1, stable_afl@2" in err


def test_explain_rebuilds_the_version_of_the_record() -> None:
    from safl_bench.analysis.explain import rebuild_method
    from safl_bench.run.runner import method_info

    small = {"width": 4, "encoder_width": 4, "code_size": 8, "hidden": 8}
    method = reg.make_method("stable_afl@1", weights="untrained", **small)
    record = dataclasses.replace(make_record("stable_afl"), method=method_info(method))
    rebuilt = rebuild_method(record)  # a bare name would be version 2
    assert type(rebuilt) is type(method) and rebuilt.version == "1"
    maps = np.random.default_rng(0).random((2, 64, 64)).astype(np.float32)
    np.testing.assert_array_equal(rebuilt.describe(maps), method.describe(maps))
