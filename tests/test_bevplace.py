"""BEVPlace: the shipped (authors') weights, the plain port against the fast path, rotation
invariance, input checks and the refusal of unsafe or ill-fitting checkpoints."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

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


pytestmark = pytest.mark.usefixtures("one_torch_thread")


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


@pytest.mark.parametrize(("n", "c", "h", "w"), [(1, 16, 151, 151), (3, 32, 7, 9), (2, 32, 1, 2)])
def test_fused_instance_norm_equals_the_torch_ops(n: int, c: int, h: int, w: int) -> None:
    """The numba kernel against the former torch ops (instance norm, ReLU) and, with `unit`,
    against instance norm followed by the per-pixel L2 normalisation."""
    from baselines.bevplace_net import channel_l2_normalize

    x = (torch.randn(n, c, h, w, generator=torch.Generator().manual_seed(c + h)) * 3 + 1)
    x = x.contiguous(memory_format=torch.channels_last)
    want = bevplace._instance_norm_torch(x.clone())
    got = bevplace._instance_norm(x.clone())
    assert got.is_contiguous(memory_format=torch.channels_last)
    assert float((got - want).abs().max()) < 1e-5
    unit = bevplace._instance_norm(x.clone(), relu=False, unit=True)
    want_unit = channel_l2_normalize(bevplace._instance_norm_torch(x.clone(), relu=False), dim=1)
    assert float((unit - want_unit).abs().max()) < 1e-5
    # NCHW input is taken too (made channels-last first)
    assert float((bevplace._instance_norm(x.contiguous()) - want).abs().max()) < 1e-5


def test_fast_path_equals_the_plain_port_at_the_published_size(method: BevPlace) -> None:
    """Three 151 x 151 views (BEVPlace's image size, every canvas of the group), batched 2 + 1
    (a partial batch): the fast path within float32 round-off of the plain port, and the
    torch thread count left as it was (numba's threads follow torch's inside)."""
    views = sample_views("topview", n=3, size=151, seed=11)
    threads = torch.get_num_threads()
    fast = BevPlace(batch_size=2).describe(views)
    assert torch.get_num_threads() == threads
    plain = BevPlace(fast=False).describe(views)
    assert float(np.abs(fast - plain).max()) < 1e-5
    assert np.array_equal(fast, BevPlace(batch_size=3).describe(views))  # batching changes nothing


def test_multiply_adds_of_the_bound() -> None:
    from baselines import bevplace_bench

    macs = bevplace_bench.multiply_adds(151)
    assert macs["total"] == macs["per_copy_cnn"] + macs["group_cnn"] + macs["netvlad"]
    assert 13.1e9 < macs["total"] < 13.3e9 and 7.4e9 < macs["group_cnn"] < 7.6e9


_FAKE_NETWORK = {
    "__init__.py": "",
    "bevplace.py": (
        "import torch\n"
        "from network.netvlad import NetVLAD\n"
        "class BEVPlace(torch.nn.Module):\n"
        "    def __init__(self):\n"
        "        super().__init__()\n"
        "        self.netvlad = NetVLAD().cuda()  # the real code calls .cuda() too\n"
        "    def forward(self, inputs):\n"
        "        imgs, pts = inputs\n"
        "        return torch.nn.functional.normalize(imgs[0].mean(dim=(1, 2, 3))[:, None].expand(-1, 8192), dim=1)\n"),
    "netvlad.py": (
        "import torch\n"
        "class NetVLAD(torch.nn.Module):\n"
        "    def __init__(self):\n"
        "        super().__init__()\n"
        "        self.centroids = torch.nn.Parameter(torch.zeros(64, 128))\n"),
    "groupnet.py": "group_config = None\n",
    "utils.py": (
        "import torch\n"
        "from skimage.io import imread\n"
        "class TransformerCV:\n"
        "    def __init__(self, config):\n"
        "        pass\n"
        "    def transform(self, img, pts):\n"
        "        return {'img': [img] * 25, 'pts': [pts] * 25}\n"
        "    @staticmethod\n"
        "    def postprocess_transformed_imgs(results):\n"
        "        return ([torch.tensor(i).permute(2, 0, 1) for i in results['img']],\n"
        "                [torch.tensor(p) for p in results['pts']])\n"),
}


@pytest.mark.slow
def test_bench_bevplace_runs_the_authors_code_side_by_side(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`bench bevplace` imports a `network/` folder at run time (a stand-in with the authors'
    interface here: .cuda() in its constructor, skimage imported), times both, prints both
    ratios; the torch thread count is respected."""
    from baselines import bevplace_bench
    from safl_bench.cli import main

    folder = tmp_path / "reference-0000000"
    (folder / "network").mkdir(parents=True)
    for name, text in _FAKE_NETWORK.items():
        (folder / "network" / name).write_text(text)
    fake_state = {"netvlad.centroids": torch.zeros(64, 128)}
    code = bevplace_bench.AuthorsCode(folder, fake_state)
    assert code.describe(sample_views("topview", n=2, size=151)).shape == (2, 8192)
    with pytest.raises(DataError, match="not BEVPlace's code"):
        bevplace_bench.AuthorsCode(tmp_path, fake_state)
    views = sample_views("topview", n=2, size=151)
    monkey_state = bevplace_bench.AuthorsCode.__init__

    def with_fake_state(self: Any, path: Any, state: Any) -> None:
        monkey_state(self, path, fake_state)

    out = tmp_path / "b.json"
    try:
        bevplace_bench.AuthorsCode.__init__ = with_fake_state  # type: ignore[method-assign]
        result = bevplace_bench.run(views, reference=folder, batch_size=2, rounds=1)
        assert main(["bench", "bevplace", "--frames", "2", "--repeats", "1", "--batch-size", "2",
                     "--threads", "1", "--reference", str(folder), "--json", str(out)]) == 0
    finally:
        bevplace_bench.AuthorsCode.__init__ = monkey_state  # type: ignore[method-assign]
    assert set(result["figures"]) == {"ours_batch1", "ours_batched", "authors_batch1", "authors_batched"}
    assert result["ratios"]["authors_over_ours_batched"] > 0 and result["ratios"]["ours_batched_over_bound"] > 0
    assert result["checks"]["max_abs_fast_vs_plain"] < 1e-5
    printed = capsys.readouterr().out
    assert "ratio authors' code / ours, batched" in printed and "ratio ours batched / compute bound" in printed
    assert json.loads(out.read_text())["env"]["torch_threads"] == 1
