"""The layout of issue #27: one folder per stage, and the old module paths still import."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

import safl_bench

PACKAGE = Path(safl_bench.__file__).parent


def test_only_the_face_errors_and_paths_stay_at_the_top() -> None:
    assert sorted(p.name for p in PACKAGE.glob("*.py")) == [
        "__init__.py", "__main__.py", "errors.py", "paths.py"]


@pytest.mark.parametrize(("old", "new"), sorted(safl_bench.MOVED_MODULES.items()))
def test_an_old_module_path_is_the_new_module(old: str, new: str) -> None:
    assert importlib.import_module(old) is importlib.import_module(new)
    assert sys.modules[old].__spec__.name == new  # its own spec, not the alias's


def test_monkeypatching_the_old_path_patches_what_the_package_uses(monkeypatch) -> None:
    from safl_bench.run import runner

    monkeypatch.setattr("safl_bench.runner.evaluate_method", "patched")
    assert runner.evaluate_method == "patched"


def test_the_old_modules_that_are_now_packages_keep_their_names() -> None:
    from safl_bench.evaluation import EvaluationConfig, cell, evaluate_method
    from safl_bench.matching import MatcherConfig, match, matcher

    assert (match, MatcherConfig) == (matcher.match, matcher.MatcherConfig)
    assert evaluate_method is cell.evaluate_method and EvaluationConfig is cell.EvaluationConfig
    with pytest.raises(AttributeError):
        _ = importlib.import_module("safl_bench.matching").no_such_name


def test_monkeypatching_an_old_module_that_is_now_a_package_patches_its_module(monkeypatch) -> None:
    from safl_bench import evaluation, matching
    from safl_bench.evaluation import cell
    from safl_bench.matching import matcher

    monkeypatch.setattr(evaluation, "describe", "patched")
    monkeypatch.setattr(matching, "match", "patched too")
    assert (cell.describe, matcher.match) == ("patched", "patched too")
    monkeypatch.undo()
    assert callable(cell.describe) and callable(matcher.match)
    assert "describe" not in vars(evaluation)  # nothing left behind on the package


def test_import_safl_bench_loads_no_stage_it_does_not_need() -> None:
    code = ("import sys, safl_bench; print(sorted(m for m in sys.modules if m.startswith("
            "('safl_bench.methods', 'safl_bench.matching', 'safl_bench.evaluation', "
            "'safl_bench.results', 'safl_bench.run', 'safl_bench.views.mapcache', "
            "'safl_bench.views.mapbuild', 'safl_bench.tasks.task', 'torch'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=PACKAGE.parent)
    assert out.stdout.strip() == "[]"


def test_the_package_face_names_what_plug_ins_use() -> None:
    from safl_bench.methods.check import check_method
    from safl_bench.methods.method import Method, register_method
    from safl_bench.results.records import load_records

    face = set(safl_bench.__all__) - {"MOVED_MODULES", "__version__"}
    assert face == set(safl_bench._FACE)
    assert (safl_bench.Method, safl_bench.register_method) == (Method, register_method)
    assert (safl_bench.check_method, safl_bench.load_records) == (check_method, load_records)
    with pytest.raises(AttributeError):
        _ = safl_bench.no_such_name
