"""Which version a bare method name runs (issue 37): per data source, the newest version of a
learned method that ships weights for it; an explicit version without them is one line naming
the versions that have them and the `train` command; untrained networks only when asked
(``--weights untrained``), and then marked in the record and every table."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest
from record_factory import make_record
from test_runner import register_tiny

from safl_bench.cli import main
from safl_bench.errors import ConfigError
from safl_bench.methods import method as reg

NAME = "test_default_version"

#: A learned method at versions 1 and 2 in a module with a `weights/` folder beside it (where
#: `shipped_weights_path` looks): its descriptor is the views' mean times a learned scale.
MODULE = '''
import numpy as np
import torch

from safl_bench.methods.method import Method


class Base(Method):
    """A learned test method."""

    name = "test_default_version"
    trainable = True

    def __init__(self, seed: int = 0):
        self.seed = seed
        self.scale = torch.ones(1)

    def describe(self, maps):
        flat = np.asarray(maps).reshape(len(maps), -1)
        return np.stack([flat.mean(axis=1), flat.std(axis=1)], axis=1).astype(np.float32) * float(self.scale)

    def state_tensors(self, parts=None):
        return {"scale": self.scale}

    def load_state_tensors(self, tensors, *, source):
        self.scale = tensors["scale"]


class V1(Base):
    version = "1"


class V2(Base):
    version = "2"
'''


@pytest.fixture
def versions(tmp_path: Path) -> Iterator[ModuleType]:
    """Versions 1 and 2 registered; 1 ships the synthetic default's weights (every source's
    fallback), 2 only top-view images' ("bev")."""
    folder = tmp_path / "pkg"
    (folder / "weights").mkdir(parents=True)
    (folder / "default_version_mod.py").write_text(MODULE)
    spec = importlib.util.spec_from_file_location("test_default_version_mod",
                                                  folder / "default_version_mod.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    for cls in (module.V2, module.V1):
        reg.register_method(cls)
    module.V1().save(folder / "weights" / f"{NAME}-v1.safetensors")
    module.V2().save(folder / "weights" / f"{NAME}-v2-bev.safetensors")
    try:
        yield module
    finally:
        if reg.method_versions(NAME):
            reg.unregister_method(NAME)
        del sys.modules[spec.name]


@pytest.fixture
def tiny_task(kitti_root: Path, safl_home: Path) -> Iterator[str]:
    yield from (ids[0] for ids in register_tiny(("Test/DefaultVersion-T1R1-v0",)))


def test_a_bare_name_runs_the_newest_version_with_weights_for_the_source(versions) -> None:
    assert reg.method_class(NAME) is versions.V2  # the registry's newest...
    assert reg.resolve_method(NAME, "synth") == f"{NAME}@1"  # ...ships no weights for synth
    assert reg.resolve_method(NAME) == f"{NAME}@1"  # None: the synthetic default
    assert reg.resolve_method(NAME, "kitti") == f"{NAME}@1"  # the synthetic weights' fallback
    assert reg.resolve_method(NAME, "bev") == f"{NAME}@2"
    assert reg.resolve_method(f"{NAME}@2", "synth") == f"{NAME}@2"  # explicit: itself
    assert reg.trained_versions(NAME, "bev") == ["1", "2"]
    assert reg.resolve_method("sad", "synth") == "sad@1"  # learns nothing: the newest
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no UserWarning, no untrained networks
        method = reg.make_method(NAME)
    assert method.version == "1" and method.weights_info["source"] == "shipped"
    assert method.weights_info["path"].endswith(f"weights/{NAME}-v1.safetensors")
    assert reg.make_method(NAME, source="bev").version == "2"
    untrained = reg.make_method(NAME, weights="untrained")  # the same version as the trained one
    assert untrained.version == "1" and untrained.weights_info == {"source": "untrained", "seed": 0}
    # a record's command names the version unless a bare name runs it on the record's data
    assert reg.method_selector(NAME, "2", "synth") == f"{NAME}@2"
    assert reg.method_selector(NAME, "2", "bev") == NAME
    assert reg.method_selector(NAME, "1", "synth") == f"{NAME}@1"  # as before: not the newest


def test_an_explicit_version_without_weights_is_one_line_naming_what_to_run(versions) -> None:
    with pytest.raises(ConfigError) as info:
        reg.make_method(f"{NAME}@2", source="synth")
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{NAME}@2 has no weights for the synthetic default; "
                              f"versions with weights for it: {NAME}@1 ")
    assert f"`safl-bench train --method {NAME}@2`" in message and "--weights untrained" in message
    reg.unregister_method(f"{NAME}@1")
    Path(versions.__file__).parent.joinpath("weights", f"{NAME}-v2-bev.safetensors").unlink()
    # no version ships weights for the source: a bare name fails too, never runs untrained
    with pytest.raises(ConfigError, match=rf"no version of '{NAME}' ships weights for it; .*"
                                          rf"--method {NAME}@2 --bev-root DIR"):
        reg.make_method(NAME, source="bev")


def test_run_a_bare_name_scores_trained_weights_and_says_which(versions, tiny_task, kitti_root,
                                                                tmp_path, capsys) -> None:
    argv = ["run", "--task", tiny_task, "--kitti-root", str(kitti_root), "--results",
            str(tmp_path), "--quiet"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main([*argv, "--method", NAME]) == 0
    assert not [w for w in caught if "UNTRAINED" in str(w.message) or "weights" in str(w.message)]
    out = capsys.readouterr().out.splitlines()
    assert out[0] == (f"{NAME}@1 on KITTI scans: its shipped weights "
                      f"test_default_version_mod/weights/{NAME}-v1.safetensors")
    assert out[1].startswith(f"{NAME}@1 — records in")
    record = json.loads(next(tmp_path.rglob("seed-0.json")).read_text())
    assert record["method"]["version"] == "1"
    assert record["method"]["params"]["weights"]["source"] == "shipped"
    assert "(untrained)" not in "\n".join(out)


def test_run_an_explicit_version_without_weights_fails_before_any_work(versions, tiny_task,
                                                                       kitti_root, tmp_path,
                                                                       capsys) -> None:
    rc = main(["run", "--method", f"{NAME}@2", "--task", tiny_task, "--kitti-root",
               str(kitti_root), "--results", str(tmp_path), "--quiet"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert (f"{NAME}@2 has no weights for KITTI scans; versions with weights for it: {NAME}@1"
            in err[0])
    assert f"`safl-bench train --method {NAME}@2 --kitti-root DIR`" in err[0]
    assert not list(tmp_path.rglob("*.json"))


def test_untrained_networks_only_when_asked_and_marked_everywhere(versions, tiny_task, kitti_root,
                                                                  tmp_path, capsys) -> None:
    from safl_bench.leaderboard.grouping import table_key
    from safl_bench.leaderboard.tables import recall_table
    from safl_bench.methods.training_data import record_untrained
    from safl_bench.records import load_record

    rc = main(["run", "--method", f"{NAME}@2", "--weights", "untrained", "--task", tiny_task,
               "--kitti-root", str(kitti_root), "--results", str(tmp_path), "--quiet"])
    assert rc == 0
    out = capsys.readouterr().out
    first = out.splitlines()[0]
    assert first.startswith(f"{NAME}@2 on KITTI scans: its UNTRAINED (random) networks, seed 0")
    assert f"{tiny_task} (untrained)" in out  # the run table
    assert "note: (untrained): scored with the method's untrained (random) networks" in out
    record = load_record(next(tmp_path.rglob("seed-0.json")))
    assert record.method.version == "2" and record.method.params["weights"]["source"] == "untrained"
    assert record_untrained(record)

    # every leaderboard table marks such rows, beside the trained ones
    trained = make_record(NAME, method_version="2")
    untrained = dataclasses.replace(
        make_record(NAME, method_version="2", recall=0.1),
        method=dataclasses.replace(trained.method, params={"weights": {"source": "untrained",
                                                                       "seed": 0}}))
    table = recall_table(table_key(trained), [untrained, trained])
    assert [row[1] for row in table.rows] == ["2", "2", "2 (untrained)", "2 (untrained)"]
    assert f"| {NAME} | 2 (untrained) | sequence |" in table.markdown()
    assert any("'(untrained)'" in note for note in table.notes)
    # and so do the all-results CSV and the figures: their own PR figure, never merged
    from safl_bench.leaderboard import build_leaderboard
    from safl_bench.leaderboard.tables import all_results_frame

    frame = all_results_frame([untrained, trained])
    assert sorted(set(frame["weights"])) == ["", "untrained"]
    report = build_leaderboard([untrained, trained], tmp_path / "board", site=False)
    pngs = sorted(p.name for p in (tmp_path / "board" / "figures").rglob("*-pr-*.png"))
    assert len(pngs) == 2 and sum("untrained" in p for p in pngs) == 1, pngs
    assert report.written
