"""A third-party plug-in package (tests/fixtures/plugin_pkg) installed with pip registers a
method through the entry-point group `safl_bench.methods` and runs end to end."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from safl_bench import method_registry as reg
from safl_bench.check import check_method, sample_views

FIXTURE = Path(__file__).parent / "fixtures" / "plugin_pkg"


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """pip-install the fixture (no deps, no build isolation) into a private target directory."""
    work = tmp_path_factory.mktemp("plugin")
    src = work / "src"
    shutil.copytree(FIXTURE, src, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    target = work / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
         "--no-index", "--disable-pip-version-check", "--target", str(target), str(src)],
        check=True, capture_output=True, timeout=120,
    )
    return target


@pytest.fixture
def on_path(installed, monkeypatch):
    monkeypatch.syspath_prepend(str(installed))
    reg.discover(refresh=True)
    yield installed
    reg.unregister_method("demo_profile")
    sys.modules.pop("safl_demo_plugin", None)


def test_plugin_registers_through_its_entry_point_and_conforms(on_path):
    info = {i.name: i for i in reg.list_methods()}["demo_profile"]
    assert info.via == "entry point demo_profile"
    assert info.distribution == "safl-demo-plugin 0.3.0"
    assert info.version == "0.3" and info.input_kind == "topview"

    method = reg.make_method("demo_profile", smooth=3)
    check_method(method)
    maps = sample_views("topview", n=6)
    d = method.describe(maps)
    assert d.shape == (6, 128)
    assert np.allclose(np.diag(method.distance(d, d)), 0.0, atol=1e-4)
    assert method.config()["name"] == "demo_profile"


def test_plugin_shows_in_the_cli_listing(installed):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(installed), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-m", "safl_bench", "list", "methods"], env=env,
                         capture_output=True, text=True, timeout=120, check=True).stdout
    line = next(row for row in out.splitlines() if row.startswith("demo_profile"))
    assert "safl_demo_plugin" in line and "safl-demo-plugin 0.3.0" in line and "entry point" in line


def test_a_broken_plugin_is_reported_not_fatal(on_path, monkeypatch):
    from importlib import metadata

    class BrokenEP:
        name = "broken_demo"
        value = "no_such_module:Nothing"
        dist = None

        def load(self):
            raise ImportError("No module named 'no_such_module'")

    real = metadata.entry_points
    monkeypatch.setattr(metadata, "entry_points", lambda **kw: [*real(**kw), BrokenEP()])
    with pytest.warns(UserWarning, match="skipping method plug-in"):
        reg.discover(refresh=True)
    names = [i.name for i in reg.list_methods(include_broken=True)]
    assert "broken_demo" in names and "sad" in names
    with pytest.raises(reg.RegistryError, match="failed to load"):
        reg.make_method("broken_demo")
    reg.unregister_method("broken_demo")
