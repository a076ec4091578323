"""The method plug-in interface: check_method catches each kind of breakage, the registry's
errors, make_method's weights choices, and safetensors-only loading."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch

from safl_bench import method_registry as reg
from safl_bench.check import MethodCheckError, check_method, sample_views
from safl_bench.cli import main as cli_main
from safl_bench.errors import ConfigError, DataError, RegistryError
from safl_bench.method import Method, as_topview
from safl_bench.weights import load_tensors, save_tensors

pytestmark = pytest.mark.usefixtures("one_torch_thread")


class Good(Method):
    """Mean of each row."""

    name = "good_rows"
    version = "1"

    def __init__(self, scale: float = 1.0):
        self.scale = scale

    def describe(self, maps):
        return (as_topview(maps).mean(axis=2) * self.scale).astype(np.float32)


def test_good_method_passes_and_fit_returns_self():
    m = Good()
    assert check_method(m) is m
    assert check_method(Good) is not None  # a class is built with its defaults
    assert m.get_params() == {"scale": 1.0}
    assert m.set_params(scale=2.0).scale == 2.0
    assert m.config()["params"] == {"scale": 2.0}
    with pytest.raises(ConfigError, match="no parameter 'nope'"):
        m.set_params(nope=1)


class F64(Good):
    def describe(self, maps):
        return super().describe(maps).astype(np.float64)


class Noisy(Good):
    def describe(self, maps):
        return super().describe(maps) + np.random.default_rng().normal(size=1).astype(np.float32)


class BatchNorm(Good):
    def describe(self, maps):
        d = super().describe(maps)
        return (d - d.mean(axis=0)).astype(np.float32)


class NegDistance(Good):
    def distance(self, queries, database):
        return -super().distance(queries, database)


class FitNoSelf(Good):
    def fit(self, maps):
        return None


class NaNs(Good):
    def describe(self, maps):
        d = super().describe(maps)
        d[0, 0] = np.nan
        return d


class Mutates(Good):
    def describe(self, maps):
        maps[0, 0, 0] = 0.5
        return super().describe(maps)


class NoName(Good):
    name = ""


class WrongRows(Good):
    def describe(self, maps):
        return super().describe(maps)[:-1]


@pytest.mark.parametrize(
    ("cls", "check"),
    [
        (F64, "describe-dtype"),
        (Noisy, "determinism"),
        (BatchNorm, "batch-independence"),
        (NegDistance, "distance-nonnegative"),
        (FitNoSelf, "fit-returns-self"),
        (NaNs, "describe-finite"),
        (Mutates, "input-unchanged"),
        (NoName, "attributes"),
        (WrongRows, "describe-shape"),
    ],
)
def test_check_method_names_the_failed_check(cls, check):
    with pytest.raises(MethodCheckError, match=rf"^\[{check}\]") as info:
        check_method(cls())
    assert info.value.check == check
    assert isinstance(info.value, AssertionError)


def test_points_views_are_generated_for_point_methods():
    class PointMean(Method):
        name = "point_mean"
        version = "1"
        input_kind = "points"

        def describe(self, maps):
            return np.stack([np.asarray(p).mean(axis=0) for p in maps]).astype(np.float32)

    check_method(PointMean())
    assert isinstance(sample_views("points"), list)


def test_builtins_are_listed_with_their_origin(capsys):
    infos = {i.name: i for i in reg.list_methods()}
    assert {"sad", "bigan", "stable_afl"} <= set(infos)
    assert infos["stable_afl"].module == "methods.stable_afl_v2"  # a bare name: the newest version
    every = {(i.name, i.version): i for i in reg.list_methods(all_versions=True)}
    assert every[("stable_afl", "1")].module == "methods.stable_afl"
    assert "safl-bench" in infos["sad"].origin
    assert cli_main(["list", "methods"]) == 0
    out = capsys.readouterr().out
    assert "stable_afl" in out and "topview" in out and "baselines.sad" in out


def test_unknown_method_suggests_close_names():
    with pytest.raises(RegistryError, match="did you mean 'stable_afl'"):
        reg.make_method("stable-afl")
    with pytest.raises(RegistryError, match="unknown method 'zzz'"):
        reg.method_class("zzz")


def test_register_rejects_duplicates_and_bad_classes():
    class Clash(Good):
        name = "sad"

    with pytest.raises(RegistryError, match="taken by"):
        reg.register_method(Clash)

    class BadName(Good):
        name = "Bad Name"

    with pytest.raises(RegistryError, match="lowercase id"):
        reg.register_method(BadName)

    class BadKind(Good):
        name = "bad_kind"
        input_kind = "pixels"

    with pytest.raises(RegistryError, match="input_kind"):
        reg.register_method(BadKind)
    with pytest.raises(RegistryError, match="not a subclass"):
        reg.register_method(int)  # type: ignore[arg-type]


def test_register_and_make_a_decorated_method():
    @reg.register_method
    class Registered(Good):
        name = "test_registered_rows"

    try:
        m = reg.make_method("test_registered_rows", scale=3.0)
        assert isinstance(m, Registered) and m.scale == 3.0
        with pytest.raises(ConfigError, match="no parameter"):
            reg.make_method("test_registered_rows", width=3)
        with pytest.raises(ConfigError, match="learns nothing"):
            reg.make_method("test_registered_rows", weights="some.safetensors")
    finally:
        reg.unregister_method("test_registered_rows")
    with pytest.raises(RegistryError):
        reg.method_class("test_registered_rows")


def _tiny_stable(**kw):
    from methods.stable_afl import StableAFL

    return StableAFL(width=4, encoder_width=4, code_size=16, hidden=16, **kw)


def test_make_method_weights_choices(monkeypatch, tmp_path):
    monkeypatch.setattr(reg, "shipped_weights_path", lambda cls, source=None: None)
    for weights in (None, "shipped"):  # no weights: an error, never the untrained networks
        with pytest.raises(ConfigError, match="stable_afl@1 has no weights for the synthetic default"):
            reg.make_method("stable_afl@1", weights=weights, width=4, encoder_width=4, code_size=16,
                            hidden=16)
    m = reg.make_method("stable_afl@1", weights="untrained", width=4, encoder_width=4, code_size=16, hidden=16, seed=3)
    assert m.weights_info == {"source": "untrained", "seed": 3}

    path = _tiny_stable(seed=5).save(tmp_path / "stable_afl.safetensors", parts=("encoder",))
    monkeypatch.setattr(reg, "shipped_weights_path", lambda cls, source=None: path)
    shipped = reg.make_method("stable_afl@1")
    assert shipped.weights_info["source"] == "shipped" and len(shipped.weights_info["sha256"]) == 64
    assert shipped.weights_info["path"] == f"methods/weights/{path.name}"
    assert shipped.seed == 5 and shipped.code_size == 16  # parameters come from the file
    maps = sample_views("topview", n=4)
    np.testing.assert_array_equal(shipped.describe(maps), _tiny_stable(seed=5).describe(maps))
    from_path = reg.make_method("stable_afl@1", weights=str(path), describe_batch=2)  # runtime param
    np.testing.assert_allclose(from_path.describe(maps), shipped.describe(maps), rtol=1e-4, atol=1e-9)
    with pytest.raises(ConfigError, match="conflicts with the weights"):
        reg.make_method("stable_afl@1", weights=str(path), code_size=32)
    assert reg.make_method("stable_afl", weights=str(path)).version == "1"  # a bare name: the file's
    with pytest.raises(DataError, match=r"weights of stable_afl@1, not of stable_afl@2; .*--method stable_afl@1"):
        reg.make_method("stable_afl@2", weights=str(path))  # version 2 never runs version 1's weights


def test_method_load_dispatches_on_the_stored_name(tmp_path):
    path = _tiny_stable().save(tmp_path / "w.safetensors")
    loaded = Method.load(path)
    assert loaded.name == "stable_afl"
    from baselines.bigan import BiGAN

    with pytest.raises(DataError, match="not 'bigan'"):
        BiGAN.load(path)


def test_loading_never_unpickles(monkeypatch, tmp_path):
    # a pickle (what torch.save writes) is refused, and torch.load/pickle are never called
    evil = tmp_path / "evil.safetensors"
    evil.write_bytes(pickle.dumps({"a": 1}))

    def forbidden(*a, **k):
        raise AssertionError("code-executing loader called")

    monkeypatch.setattr(torch, "load", forbidden)
    monkeypatch.setattr(pickle, "load", forbidden)
    monkeypatch.setattr(pickle, "loads", forbidden)
    with pytest.raises(DataError, match="not a readable safetensors"):
        Method.load(evil)
    good = _tiny_stable().save(tmp_path / "good.safetensors")
    assert Method.load(good).name == "stable_afl"
    with pytest.raises(DataError, match="does not exist"):
        load_tensors(tmp_path / "missing.safetensors")

    from safetensors.torch import save_file

    save_file({"x": torch.zeros(2)}, str(tmp_path / "foreign.safetensors"))
    with pytest.raises(DataError, match="not written by safl-bench"):
        load_tensors(tmp_path / "foreign.safetensors")
    save_tensors(tmp_path / "ckpt.safetensors", {"x": torch.zeros(2)}, {"kind": "checkpoint"})
    with pytest.raises(DataError, match="does not hold a saved method"):
        Method.load(tmp_path / "ckpt.safetensors")
