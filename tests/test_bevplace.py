"""BEVPlace: the shipped (authors') weights, the plain port against the fast path, rotation
invariance, input checks and the refusal of unsafe or ill-fitting checkpoints."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import torch

from baselines import bevplace
from baselines.bevplace import BevPlace, load_authors_checkpoint
from baselines.bevplace_net import BevPlaceNet
from safl_bench.check import check_method, sample_views
from safl_bench.errors import ConfigError, DataError
from safl_bench.method import Method
from safl_bench.method_registry import make_method, shipped_weights_path
from safl_bench.weights import file_sha256, load_tensors

AUTHORS_TENSORS = 42
AUTHORS_PARAMETERS = 456_904


@pytest.fixture(scope="module", autouse=True)
def _one_thread() -> Iterator[None]:
    """One torch thread here: the descriptors do not depend on it, and on a shared 2-core
    machine two threads wait on each other (OpenMP) and run erratically slowly."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="module")
def method() -> BevPlace:
    return BevPlace()


@pytest.fixture(scope="module")
def shipped_state() -> dict[str, torch.Tensor]:
    tensors, _ = load_tensors(bevplace.WEIGHTS_FILE)
    return tensors


def test_conforms(method: BevPlace) -> None:
    check_method(method, views=sample_views("topview", n=4, size=64))


def test_shipped_weights_load_strictly_with_the_authors_names(shipped_state: dict[str, torch.Tensor]) -> None:
    expected = bevplace.expected_tensors()
    assert {k: tuple(v.shape) for k, v in shipped_state.items()} == expected
    assert len(shipped_state) == AUTHORS_TENSORS
    assert sum(v.numel() for v in shipped_state.values()) == AUTHORS_PARAMETERS
    assert all(v.dtype == torch.float32 for v in shipped_state.values())
    assert {k.split(".")[0] for k in expected} == {"encoder", "netvlad"}
    net = BevPlaceNet()
    result = net.load_state_dict(shipped_state, strict=True)
    assert not result.missing_keys and not result.unexpected_keys
    _, meta = load_tensors(bevplace.WEIGHTS_FILE)
    assert meta["kind"] == "method" and meta["method"]["name"] == "bevplace"
    assert meta["converted_from"]["commit"].startswith("56483fd9")
    assert (bevplace.WEIGHTS_FILE.parent / "BEVPLACE-LICENSE").is_file()


def test_make_method_runs_the_shipped_weights(shipped_state: dict[str, torch.Tensor]) -> None:
    m = make_method("bevplace")
    assert isinstance(m, BevPlace) and m.input_size is None
    info = m.config()["weights"]
    assert info == {"source": "shipped", "path": "baselines/weights/bevplace.safetensors",
                    "sha256": file_sha256(bevplace.WEIGHTS_FILE)}
    assert all(torch.equal(v, shipped_state[k]) for k, v in m.net.state_dict().items())
    assert shipped_weights_path(BevPlace) == bevplace.WEIGHTS_FILE
    assert isinstance(make_method("bevplace", weights="shipped"), BevPlace)
    with pytest.raises(ConfigError, match="no untrained variant"):
        make_method("bevplace", weights="untrained")


def test_saved_file_and_authors_checkpoint_load_back(method: BevPlace, tmp_path: Path,
                                                     shipped_state: dict[str, torch.Tensor]) -> None:
    views = sample_views("topview", n=1, size=64)
    want = method.describe(views)
    saved = method.save(tmp_path / "copy.safetensors")
    again = Method.load(saved)
    assert isinstance(again, BevPlace)
    np.testing.assert_array_equal(again.describe(views), want)
    ckpt = tmp_path / "checkpoint.pth.tar"
    torch.save({"epoch": 15, "state_dict": shipped_state}, ckpt)
    for loaded in (load_authors_checkpoint(ckpt), make_method("bevplace", weights=str(ckpt))):
        assert isinstance(loaded, BevPlace)
        assert loaded.config()["weights"]["source"] == "authors checkpoint"
        np.testing.assert_array_equal(loaded.describe(views), want)


def test_fast_path_equals_the_plain_port(method: BevPlace) -> None:
    views = sample_views("topview", n=2, size=96, seed=3)
    fast = method.describe(views)
    plain = BevPlace(fast=False).describe(views)
    assert fast.shape == (2, 8192) and fast.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(fast, axis=1), 1.0, atol=1e-5)
    assert float(np.abs(fast - plain).max()) < 1e-4


def test_rotation_by_90_degrees_barely_moves_the_descriptor(method: BevPlace) -> None:
    views = sample_views("topview", n=2, size=64, seed=5)
    turned = np.ascontiguousarray(np.rot90(views, 1, axes=(1, 2)))
    d = method.describe(np.concatenate([views, turned]))
    same = float(((d[0] - d[2]) ** 2).sum())
    other = float(((d[0] - d[1]) ** 2).sum())
    assert same < 0.5 * other, (same, other)


def test_too_small_or_non_square_views_are_refused(method: BevPlace) -> None:
    smallest = bevplace.minimum_size()
    assert smallest == 56
    method.describe(np.zeros((1, smallest, smallest), np.float32))
    with pytest.raises(DataError, match=r"40x40"):
        method.describe(np.zeros((1, 40, 40), np.float32))
    with pytest.raises(DataError, match=r"64x80"):
        method.describe(np.zeros((1, 64, 80), np.float32))
    assert method.describe(np.zeros((0, 64, 64), np.float32)).shape == (0, 8192)


_PAYLOAD_RAN: list[str] = []


def _payload(*args: object) -> None:
    _PAYLOAD_RAN.append("ran")


class _Payload:
    def __reduce__(self) -> tuple[object, tuple[object, ...]]:
        return (_payload, ("rm -rf /",))


def test_a_checkpoint_that_would_run_code_is_refused_in_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "evil.pth.tar"
    torch.save({"epoch": 1, "state_dict": {"x": _Payload()}}, bad)
    with pytest.raises(DataError) as err:
        load_authors_checkpoint(bad)
    message = str(err.value)
    assert "\n" not in message and str(bad) in message and "weights_only" in message
    assert not _PAYLOAD_RAN


def test_missing_or_extra_tensors_are_named(tmp_path: Path, shipped_state: dict[str, torch.Tensor]) -> None:
    short = dict(shipped_state)
    del short["netvlad.centroids"]
    path = tmp_path / "short.pth.tar"
    torch.save({"epoch": 1, "state_dict": short}, path)
    with pytest.raises(DataError, match=r"1 missing \(netvlad\.centroids\)"):
        load_authors_checkpoint(path)
    extra = {**shipped_state, "netvlad.mean": torch.ones(8, 1), "netvlad.bias": torch.ones(1)}
    path = tmp_path / "extra.pth.tar"
    torch.save({"epoch": 1, "state_dict": extra}, path)
    with pytest.raises(DataError, match=r"2 unexpected \(netvlad\.mean, netvlad\.bias\)"):
        load_authors_checkpoint(path)
    wrong = {**shipped_state, "netvlad.centroids": torch.zeros(32, 128)}
    path = tmp_path / "wrong.pth.tar"
    torch.save({"epoch": 1, "state_dict": wrong}, path)
    with pytest.raises(DataError, match=r"netvlad\.centroids \(32, 128\)"):
        load_authors_checkpoint(path)
    with pytest.raises(DataError, match="does not exist"):
        load_authors_checkpoint(tmp_path / "nothing.pth.tar")


def test_transformed_copies_follow_the_authors_geometry() -> None:
    copies = bevplace.group_copies(151)
    assert len(copies) == 25
    assert [(c.width, c.height) for c in copies[:5]] == [(151, 151), (214, 214), (151, 151), (214, 214), (151, 151)]
    assert [c.width for c in copies[2::5]] == [151, 76, 38, 19, 9]
    assert bevplace.sample_points(151).shape == (841, 2)
    # the 0-degree copy at scale 1 is the image itself; at scale 1/2 every other pixel
    taps = bevplace.warp_taps(151, 2)
    assert np.array_equal(taps.index[0], np.arange(151 * 151)) and np.all(taps.weight[0] == 1)
    half = bevplace.warp_taps(151, 7)
    assert half.weight[0].min() == 1 and half.index[0][1] == 2


@pytest.mark.slow
def test_bench_times_it_at_the_published_size(method: BevPlace) -> None:
    from safl_bench import method_bench

    views = sample_views("topview", n=4, size=64)
    result = method_bench.bench_method(method, views, frames=1, repeats=1, batch_size=2,
                                       matrix_n=None, batched_budget_s=0.01)
    assert result["views"] == "64x64 views resampled to 151x151 for timing"
    assert result["batch1"]["per_item_ms"] > 0 and result["batched"]["n_items"] == 2
    assert "bevplace: 64x64 views resampled to 151x151" in method_bench.format_results([result])
