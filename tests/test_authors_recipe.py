"""The authors' paper-era recipe (stable_afl@2, bigan@2; CNN-GAN/Top-Mapping 25be0fd): network
shapes and TF 'SAME' padding, per-image batch norm at test time, the optimiser steps of one
iteration, training counted in iterations across epochs, a resume from a checkpoint inside an
epoch, the epoch-based @1 path unchanged, and `train --snapshot-every`.

Tiny settings throughout (16x16 maps, width 2, an 8-d code, batches of 4); the critics keep
their fixed 1024/2048-wide layers, so `gen_steps` is lowered where only the loop is tested."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
import torch
from torch import nn

from baselines.authors_nets import (
    AuthorsDecoder,
    AuthorsEncoder,
    AuthorsImageCritic,
    AuthorsJointCritic,
    _SameConv,
    _SameDeconv,
    init_authors,
)
from baselines.bigan_v2 import BiGAN2
from methods.stable_afl_v2 import StableAFL2
from safl_bench.check import sample_views
from safl_bench.errors import ConfigError
from safl_bench.methods.method import make_method, method_class

TINY = {"image_size": 16, "width": 2, "code_size": 8, "batch_size": 4}


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def bigan(**kw):
    return BiGAN2(**{**TINY, "iterations": 5, "gen_steps": 2, **kw})


def states(method) -> dict[str, torch.Tensor]:
    return {f"{n}.{k}": v for n, net in method.nets.items() for k, v in net.state_dict().items()}


def assert_same_weights(a, b) -> None:
    sa, sb = states(a), states(b)
    assert sa.keys() == sb.keys()
    for k in sa:
        assert torch.equal(sa[k], sb[k]), k


def read_log(directory) -> list[dict]:
    return [json.loads(line) for line in (directory / "log.jsonl").read_text().splitlines()]


# -- networks ------------------------------------------------------------------------------------

def test_versions_are_registered_and_a_bare_name_is_the_newest():
    assert method_class("stable_afl@2") is StableAFL2 and method_class("bigan@2") is BiGAN2
    assert method_class("stable_afl") is StableAFL2 and method_class("bigan") is BiGAN2
    assert method_class("stable_afl@1").version == "1" and method_class("bigan@1").version == "1"


def test_output_shapes_of_each_network():
    x = torch.rand(3, 1, 16, 16) * 2 - 1
    z = torch.randn(3, 8)
    assert AuthorsEncoder(16, 8, 2)(x).shape == (3, 8)
    out = AuthorsDecoder(16, 8, 2)(z)
    assert out.shape == (3, 1, 16, 16) and float(out.detach().abs().max()) <= 1.0  # tanh
    assert AuthorsImageCritic(16, 2)(x).shape == (3, 1024)
    assert AuthorsJointCritic(16, 8, 2)(x, z).shape == (3,)


def _layers(net: nn.Module, kind: type) -> list[tuple[int, ...]]:
    return [tuple(m.weight.shape) for m in net.modules() if isinstance(m, kind)]


def test_the_authors_sizes_at_64x64():
    """module.py:116-190, 231-269, 297-365 at 25be0fd with img_filter 64, code_dim 512,
    dX_dim = dZ_dim = 1024, dJ_dim 2048 (one input channel where theirs has three)."""
    convs = [(64, 1, 5, 5), (128, 64, 5, 5), (256, 128, 5, 5), (512, 256, 5, 5)]
    enc = AuthorsEncoder()
    assert _layers(enc, nn.Conv2d) == convs and _layers(enc, nn.Linear) == [(512, 4 * 4 * 512)]
    assert _layers(enc, nn.BatchNorm2d) == [(64,), (128,), (256,), (512,)]
    dec = AuthorsDecoder()
    assert _layers(dec, nn.Linear) == [(4 * 4 * 512, 512)]
    # ConvTranspose2d weights are (in, out, k, k): 512 -> 256 -> 128 -> 64 -> 1
    assert _layers(dec, nn.ConvTranspose2d) == [(512, 256, 5, 5), (256, 128, 5, 5), (128, 64, 5, 5), (64, 1, 5, 5)]
    assert _layers(dec, nn.BatchNorm2d) == [(512,), (256,), (128,), (64,)]
    assert _layers(AuthorsImageCritic(), nn.Linear) == [(1024, 8192)]
    joint = AuthorsJointCritic()
    assert _layers(joint, nn.Conv2d) == convs
    assert _layers(joint, nn.Linear) == [(1024, 8192), (1024, 512), (1024, 1024), (2048, 2048), (2048, 2048), (1, 2048)]
    drops = [m.p for m in joint.modules() if isinstance(m, nn.Dropout)]
    assert len(drops) == 5 and all(p == pytest.approx(0.2) for p in drops)  # keep = 0.8
    with pytest.raises(ConfigError, match="power of two"):
        AuthorsEncoder(image_size=48)


def test_initialisation_is_the_authors():
    net = AuthorsJointCritic(16, 8, 2).requires_grad_(False)
    init_authors(net)
    big = net.joint[1].weight
    assert float(big.mean()) == pytest.approx(0.0, abs=1e-3) and float(big.std()) == pytest.approx(0.02, rel=0.02)
    assert all(float(m.bias.abs().max()) == 0.0 for m in net.modules() if isinstance(m, nn.Linear | nn.Conv2d))
    bn = net.x_net.norm
    assert float(bn.weight.mean()) == pytest.approx(1.0, abs=0.01) and float(bn.bias.abs().max()) == 0.0
    assert float(bn.weight.std()) == pytest.approx(0.02, rel=0.2)


def test_same_padding_is_tensorflows_one_before_two_after():
    conv = _SameConv(1, 1)
    assert conv(torch.zeros(1, 1, 16, 16)).shape == (1, 1, 8, 8)
    with torch.no_grad():
        conv.conv.weight.copy_(torch.arange(25.0).view(1, 1, 5, 5))
        conv.conv.bias.zero_()
        delta = torch.zeros(1, 1, 16, 16)
        delta[0, 0, 0, 0] = 1.0
        # TF 'SAME', 5x5 stride 2 on an even size pads 1 before: out[0,0] sees x[0,0] at kernel
        # (1,1). PyTorch's symmetric padding=2 would put it at (2,2) (a half-pixel shift).
        assert float(conv(delta)[0, 0, 0, 0]) == 6.0
        last = torch.zeros(1, 1, 16, 16)
        last[0, 0, 15, 15] = 1.0  # 2 after: out[7,7] covers rows 13..17, x[15] at kernel row 2
        assert float(conv(last)[0, 0, 7, 7]) == 12.0


def test_transposed_conv_inverts_the_size_and_is_the_adjoint():
    conv, deconv = _SameConv(3, 2), _SameDeconv(2, 3)
    with torch.no_grad():
        deconv.deconv.weight.copy_(conv.conv.weight)  # (out, in, k, k) of the conv = (in, out, k, k) here
        conv.conv.bias.zero_()
        deconv.deconv.bias.zero_()
        x, y = torch.randn(1, 3, 16, 16, dtype=torch.float64), torch.randn(1, 2, 8, 8, dtype=torch.float64)
        conv, deconv = conv.double(), deconv.double()
        assert deconv(y).shape == (1, 3, 16, 16)
        # <conv(x), y> == <x, deconv(y)>: TF's conv2d_transpose is the gradient of its conv2d
        assert float((conv(x) * y).sum()) == pytest.approx(float((x * deconv(y)).sum()), rel=1e-12)


# -- batch norm at test time ---------------------------------------------------------------------

def test_describe_normalises_each_map_by_itself():
    maps = sample_views("topview", n=5)
    m = StableAFL2(**TINY)
    batch = m.describe(maps)
    alone = np.concatenate([m.describe(maps[i : i + 1]) for i in range(len(maps))])
    np.testing.assert_allclose(batch, alone, rtol=1e-5, atol=1e-6)
    # the same numbers as the authors' graph: training-mode batch norm fed one map at a time
    enc = copy.deepcopy(m.encoder).train()
    with torch.no_grad():
        x = m.to_input(maps)
        one_by_one = torch.cat([enc(x[i : i + 1]) for i in range(len(x))]).numpy()
    np.testing.assert_allclose(batch, one_by_one, rtol=1e-5, atol=1e-6)
    running = StableAFL2(**TINY, test_stats="running")
    assert_same_weights(m, running)  # only the test-time statistics differ
    assert not np.allclose(running.describe(maps), batch, atol=1e-3)
    with pytest.raises(ConfigError, match="test_stats"):
        StableAFL2(**TINY, test_stats="batch")


# -- one iteration ---------------------------------------------------------------------------------

def _one_iteration(method) -> dict[str, set[int]]:
    method.optims = method.build_optimizers()
    for net in method.nets.values():
        net.train()
    x = method.to_input(sample_views("topview", n=4))
    stats = method.train_step([x], torch.Generator().manual_seed(0))
    assert all(np.isfinite(v) for v in stats.values())
    return {name: {int(s["step"]) for s in opt.state.values()} for name, opt in method.optims.items()}


def _params(method, *nets: str) -> set[int]:
    return {id(p) for n in nets for p in method.nets[n].parameters()}


def test_stable_afl_iteration_steps_in_the_authors_counts():
    """model.py:263-274 at 25be0fd: joint critic 1, then g_iter = 8 x (joint generator, cycle),
    then image side critic 1 and decoder side 1; var_lists of :191-204."""
    m = StableAFL2(**TINY)
    steps = _one_iteration(m)
    assert steps == {"joint": {1}, "generator": {8}, "cycle": {8}, "data_side": {1}, "decoder_side": {1}}
    owned = {name: {id(p) for g in opt.param_groups for p in g["params"]} for name, opt in m.optims.items()}
    assert owned == {"joint": _params(m, "joint"), "generator": _params(m, "encoder", "decoder"),
                     "cycle": _params(m, "encoder", "decoder"), "data_side": _params(m, "data_side"),
                     "decoder_side": _params(m, "decoder")}
    assert all(opt.param_groups[0]["betas"] == (0.5, 0.999) and opt.param_groups[0]["lr"] == 2e-4
               for opt in m.optims.values())


def test_bigan_iteration_steps_in_the_authors_counts():
    """model.py:308-312 at 25be0fd: joint critic 1, joint generator g_iter = 8."""
    m = BiGAN2(**TINY)
    assert _one_iteration(m) == {"joint": {1}, "generator": {8}}
    assert "data_side" not in m.nets


def test_defaults_are_the_authors():
    s, b = StableAFL2(image_size=16, width=2), BiGAN2(image_size=16, width=2)
    for m in (s, b):
        assert (m.code_size, m.prior, m.test_stats, m.gen_steps, m.lr, m.beta1, m.batch_size) == \
               (512, "normal", "image", 8, 2e-4, 0.5, 64)
    assert (s.iterations, s.cycle_weight, s.side_weight) == (4900, 0.1, 0.1)
    assert b.iterations == 2200
    with pytest.raises(ConfigError, match="iterations"):
        BiGAN2(**TINY, iterations=0)
    with pytest.raises(ConfigError, match="gen_steps"):
        BiGAN2(**TINY, gen_steps=0)


# -- the training loop -----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def maps():
    return sample_views("topview", n=9)  # batches of 4: 2 steps an epoch, one map dropped


@pytest.fixture(scope="module")
def straight(maps):
    done: list[int] = []
    before = torch.get_num_threads()
    torch.set_num_threads(1)  # as the tests run (one_torch_thread), whatever the fixture order
    try:
        method = bigan().fit(maps, step_callback=lambda step, _: done.append(step))
    finally:
        torch.set_num_threads(before)
    assert done == [1, 2, 3, 4, 5]
    return method


def test_iterations_are_counted_across_epochs_and_stop_inside_one(maps, tmp_path):
    m = bigan(iterations=5).fit(maps, checkpoint_dir=tmp_path)
    log = read_log(tmp_path)
    assert [(r["epoch"], r["steps"]) for r in log] == [(1, 2), (2, 2), (3, 1)]
    assert all("loss_dj" in r and "loss_g" in r for r in log)
    assert int(next(iter(m.optims["joint"].state.values()))["step"]) == 5


def test_a_resumed_run_ends_with_the_weights_of_a_straight_one(maps, straight, tmp_path):
    bigan(iterations=3).fit(maps, checkpoint_dir=tmp_path, checkpoint_every=1)  # ends inside epoch 2
    resumed = bigan(iterations=5).fit(maps, checkpoint_dir=tmp_path, checkpoint_every=1)
    assert_same_weights(straight, resumed)
    log = read_log(tmp_path)
    assert [(r["epoch"], r["steps"], r.get("resumed_at_step")) for r in log] == [(1, 2, None), (2, 2, 1), (3, 1, None)]


class _Killed(Exception):
    pass


def test_an_interrupted_run_resumes_inside_the_epoch(maps, straight, tmp_path):
    def kill_at_4(step, _):
        if step == 4:  # before step 4's checkpoint: the newest is step 3's, inside epoch 2
            raise _Killed

    with pytest.raises(_Killed):
        bigan().fit(maps, checkpoint_dir=tmp_path, checkpoint_every=1, step_callback=kill_at_4)
    done: list[int] = []
    resumed = bigan().fit(maps, checkpoint_dir=tmp_path, checkpoint_every=1,
                          step_callback=lambda step, _: done.append(step))
    assert done == [4, 5]
    assert_same_weights(straight, resumed)
    with pytest.raises(ConfigError, match="other settings"):
        bigan(lr=1e-3).fit(maps, checkpoint_dir=tmp_path)
    with pytest.raises(ConfigError, match="checkpoint_every"):
        bigan().fit(maps, checkpoint_every=0)


#: stable_afl@1 and bigan@1 (width 4, code 8, hidden 16, batches of 4, 2 epochs, seed 0, one
#: thread) on sample_views("topview", n=12): En of the first three maps, computed with the code
#: at 0ff1951, before training could count iterations (the current code gave the same digits)
EPOCH_PATH = {
    "stable_afl@1": [
        [-0.0164887, -0.0210626, 0.0098301, -0.0500951, 0.0038445, 0.0102202, -0.0121977, 0.0195987],
        [-0.0164462, -0.0211156, 0.0097199, -0.0498879, 0.0039172, 0.0099932, -0.0122687, 0.0196822],
        [-0.0164806, -0.021117, 0.0097791, -0.0499085, 0.0038842, 0.0100994, -0.0121595, 0.0197281]],
    "bigan@1": [
        [-0.0054458, -0.0016368, 0.0037263, 0.0100793, 0.0051802, -0.0100839, 0.020367, 0.0163826],
        [-0.0056456, -0.0016854, 0.0036495, 0.010284, 0.0050695, -0.010189, 0.0203218, 0.0163849],
        [-0.005588, -0.0018032, 0.0035267, 0.0102773, 0.0047859, -0.0100434, 0.0203152, 0.016467]],
}


@pytest.mark.parametrize("name", sorted(EPOCH_PATH))
def test_the_epoch_based_path_gives_what_it_gave(name, tmp_path):
    extra = {"critic_steps": 2} if name.startswith("stable_afl") else {}
    m = method_class(name)(width=4, encoder_width=4, code_size=8, hidden=16, batch_size=4, epochs=2,
                           seed=0, **extra).fit(sample_views("topview", n=12), checkpoint_dir=tmp_path)
    np.testing.assert_allclose(m.describe(sample_views("topview", n=12)[:3]), EPOCH_PATH[name],
                               rtol=1e-4, atol=2e-7)
    steps = 12 // (4 * m.batches_per_step)  # stable_afl@1's step takes 3 batches here (2 critic steps)
    assert [(r["epoch"], r["steps"]) for r in read_log(tmp_path)] == [(1, steps), (2, steps)]


# -- train --snapshot-every ------------------------------------------------------------------------

class _FakeSource:
    kind = "synth"
    label = "fake"


def test_train_snapshot_every(tmp_path, monkeypatch, capsys, maps):
    from safl_bench.cli import main
    from safl_bench.cli import train as train_cli

    assert main(["train", "--method", "bigan@2", "--snapshot-every", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--snapshot-every" in err[0] and "0" in err[0]

    monkeypatch.setattr(train_cli, "load_training_maps", lambda *a, **k: (maps, {"01": len(maps)}))
    monkeypatch.setattr("safl_bench.sources.synth_source", lambda *a, **k: _FakeSource())
    out = tmp_path / "run"
    argv = ["train", "--method", "bigan@2", "--out", str(out), "--no-progress", "--val-task", "none",
            "--snapshot-every", "2", "--set", "iterations=3", "--set", "gen_steps=1"]
    argv += [a for k, v in TINY.items() for a in ("--set", f"{k}={v}")]
    assert main(argv) == 0
    snaps = sorted(p.name for p in (out / "snapshots").iterdir())
    assert snaps == ["bigan-step000002.safetensors"]
    snap = make_method("bigan", weights=out / "snapshots" / snaps[0])
    final = make_method("bigan", weights=out / "bigan.safetensors")
    assert isinstance(snap, BiGAN2) and snap.describe(maps).shape == (len(maps), 8)
    assert not np.array_equal(snap.describe(maps), final.describe(maps))  # step 2, not step 3
    assert [(r["epoch"], r["steps"]) for r in read_log(out)] == [(1, 2), (2, 1)]
