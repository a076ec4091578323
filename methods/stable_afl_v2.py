"""Stable-AFL version 2: the training recipe of the authors' paper-era code.

`stable_afl@1` (methods/stable_afl.py) is built from the paper's text. Version 2 follows the code
that trained the Stable-AFL features of the paper's figures, CNN-GAN/Top-Mapping at commit
25be0fd (2017-10-17; `src/plot/plotPaper2.py:20,26` names that run `ALI_CLC/r14_Cout_0.1_X_LS`
and its checkpoint 49, i.e. 4900 iterations), method `ALI_CLC` (`parameters.py:34`) with
`Loss` = `LSGAN` (:36; the flag is read by no code: model.py:42-43 fixes both losses to
`mae_criterion`). Lines below are of `src/model/model.py` at 25be0fd unless named.

Networks: `baselines/authors_nets.py` (64-128-256-512 5x5 convolutions with batch norm, a
512-d code, the 1024-d image critic and the dropout joint critic of `src/module/module.py`).

Losses, all least squares (`mae_criterion` is the mean squared error, module.py:373-374):

* joint critic (:92): 0.5 [(D_J(x, En(x)) - 1)^2 + D_J(De(z), z)^2], on D_J;
* joint generator (:93): the labels swapped, on En and De (`var_gen`, :162-163);
* cycle (:89-90): `cycle` = 0.1 (parameters.py:14) x [MSE(x, De(En(x))) + MSE(z, En(De(z)))],
  per-element means, on En and De with an Adam of its own (:191-192);
* image side critic (:98-99, on D_X, :203-204): `side_D` = 0.1 (parameters.py:13) x 0.5
  [(D_X(x) - 1)^2 + D_X(De(z))^2] over D_X's 1024 outputs; decoder side loss (:96)
  0.1 x (D_X(De(z)) - 1)^2 on De alone (:201-202);
* the code-side critic D_Z and the encoder's side loss are built (:95, :100-101; optimisers
  :199-200, :205-206) but never stepped: the loop (:263-274) runs neither, and the lines that
  would (:300, :303) sit in a disabled block (:288-307), so they are not trained here either; no
  weight clipping is run (the clip ops of :165-168 are never run; :266 is commented out).

One iteration (:263-274), on ONE batch of `batch_size` = 64 maps (parameters.py:46) and 64
codes z ~ N(0, I) (`NoiseSampler`, src/data/__init__.py:38-45; `sample_size` = 64,
parameters.py:19), drawn once (:265) and fed to every step of the iteration: one joint-critic
step; then `g_iter` = 8 times (parameters.py:48) a joint-generator step and a cycle step; then
one image-side critic step and one decoder side step. Every loss has its own Adam, lr 2e-4,
beta1 0.5 (parameters.py:11-12; :191-206): the joint-generator and the cycle losses step the
same En and De with two optimisers. Batches: the maps shuffled, taken in order, reshuffled when
fewer than a batch remain (`DataSampler`, src/data/__init__.py:5-34): our epochs.
`iterations` = 4900 (plotPaper2.py:26: checkpoint 49; the weights are saved every `save_step` =
50 iterations under the iteration count, parameters.py:39, :322-323, :514-515, and tested as
`%d00`, :338, :462-465). Training data: KITTI 01-08, every frame (:240-247).

Where the paper says otherwise, its value is a parameter: `code_size` (the paper's §IV.D
descriptor is 1024 floats; the code 512), `prior` ("normal" here; "uniform" is BiGAN's).
`test_stats` (see authors_nets): "image", each map normalised by its own statistics as their
batch-1 test graph does. Descriptors are compared by the harness's distance (squared L2 by
default; the `authors` matcher preset compares plain L2, as utils.py:76 at 25be0fd does).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from baselines.authors_nets import (
    AuthorsDecoder,
    AuthorsEncoder,
    AuthorsImageCritic,
    AuthorsJointCritic,
    init_authors,
    least_squares,
)
from safl_bench.errors import ConfigError
from safl_bench.methods.method import register_method
from safl_bench.methods.training import AdversarialMethod

#: the authors' code this version follows
AUTHORS_COMMIT = "25be0fd"


def adam(params: object, lr: float, beta1: float) -> torch.optim.Optimizer:
    """tf.train.AdamOptimizer(lr, beta1=beta1): beta2 0.999, epsilon 1e-8 (TF's defaults)."""
    return torch.optim.Adam(params, lr=lr, betas=(beta1, 0.999), eps=1e-8)  # type: ignore[arg-type]


def step(optimizer: torch.optim.Optimizer, loss: torch.Tensor) -> float:
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    optimizer.step()
    return float(loss.detach())


def frozen(net: nn.Module) -> _Frozen:
    """Within the block `net`'s parameters take no gradient (the step updates other networks;
    this only saves the work of gradients that the step would throw away)."""
    return _Frozen(net)


class _Frozen:
    def __init__(self, net: nn.Module):
        self.params = [p for p in net.parameters() if p.requires_grad]

    def __enter__(self) -> None:
        for p in self.params:
            p.requires_grad_(False)

    def __exit__(self, *exc: object) -> None:
        for p in self.params:
            p.requires_grad_(True)


def joint_losses(dj: nn.Module, x: torch.Tensor, ex: torch.Tensor, gz: torch.Tensor,
                 z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """model.py:92-93 at 25be0fd: (critic loss, generator loss) of the least-squares joint GAN."""
    real, fake = dj(x, ex), dj(gz, z)
    critic = 0.5 * (least_squares(real, 1.0) + least_squares(fake, 0.0))
    generator = 0.5 * (least_squares(real, 0.0) + least_squares(fake, 1.0))
    return critic, generator


class AuthorsRecipe(AdversarialMethod):
    """Shared parameters and networks of the authors' paper-era recipe (stable_afl@2, bigan@2)."""

    version = "2"
    #: the iteration count of the checkpoint the authors' figures use (set per method)
    default_iterations = 4900

    def __init__(
        self,
        code_size: int = 512,
        image_size: int = 64,
        width: int = 64,
        prior: str = "normal",
        test_stats: str = "image",
        gen_steps: int = 8,
        cycle_weight: float = 0.1,
        side_weight: float = 0.1,
        lr: float = 2e-4,
        beta1: float = 0.5,
        iterations: int | None = None,
        batch_size: int = 64,
        seed: int = 0,
        describe_batch: int = 64,
        device: str = "cpu",
    ):
        self.code_size = code_size
        self.image_size = image_size
        self.width = width
        self.encoder_width = width
        self.prior = prior
        self.test_stats = test_stats
        self.gen_steps = gen_steps
        self.cycle_weight = cycle_weight
        self.side_weight = side_weight
        self.lr = lr
        self.beta1 = beta1
        self.iterations = self.default_iterations if iterations is None else iterations
        self.epochs = 1  # unused: training counts `iterations`
        self.batch_size = batch_size
        self.seed = seed
        self.describe_batch = describe_batch
        self.device = device
        if not isinstance(gen_steps, int) or gen_steps < 1:
            raise ConfigError(f"{self.name}: gen_steps must be a positive integer, got {gen_steps!r}")
        self._init_networks()

    @property
    def input_size(self) -> int:
        """The networks take `image_size` x `image_size` maps."""
        return self.image_size

    def build_networks(self) -> dict[str, nn.Module]:
        nets: dict[str, nn.Module] = {
            "encoder": AuthorsEncoder(self.image_size, self.code_size, self.width, self.test_stats),
            "decoder": AuthorsDecoder(self.image_size, self.code_size, self.width),
            "joint": AuthorsJointCritic(self.image_size, self.code_size, self.width),
        }
        for net in nets.values():
            init_authors(net)
        return nets

    def _adam(self, *nets: str) -> torch.optim.Optimizer:
        return adam([p for n in nets for p in self.nets[n].parameters()], self.lr, self.beta1)

    def _joint_critic_step(self, x: torch.Tensor, z: torch.Tensor) -> float:
        en, de = self.nets["encoder"], self.nets["decoder"]
        with torch.no_grad():
            ex, gz = en(x), de(z)
        assert self.optims is not None
        return step(self.optims["joint"], joint_losses(self.nets["joint"], x, ex, gz, z)[0])

    def _joint_generator_step(self, x: torch.Tensor, z: torch.Tensor) -> float:
        en, de = self.nets["encoder"], self.nets["decoder"]
        assert self.optims is not None
        with frozen(self.nets["joint"]):
            return step(self.optims["generator"], joint_losses(self.nets["joint"], x, en(x), de(z), z)[1])


@register_method
class StableAFL2(AuthorsRecipe):
    """Stable-AFL as its authors' paper-era code trained it (least squares, cycle, image side critic)."""

    name = "stable_afl"

    def build_networks(self) -> dict[str, nn.Module]:
        nets = super().build_networks()
        nets["data_side"] = AuthorsImageCritic(self.image_size, self.width)
        init_authors(nets["data_side"])
        return nets

    def build_optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {
            "joint": self._adam("joint"),
            "generator": self._adam("encoder", "decoder"),
            "cycle": self._adam("encoder", "decoder"),
            "data_side": self._adam("data_side"),
            "decoder_side": self._adam("decoder"),
        }

    def train_step(self, batches: Sequence[torch.Tensor], gen: torch.Generator) -> dict[str, float]:
        """One iteration of model.py:263-274 at 25be0fd on one batch and one draw of z."""
        assert self.optims is not None
        x = batches[0]
        z = self.sample_prior(len(x), gen)
        en, de, dx = self.nets["encoder"], self.nets["decoder"], self.nets["data_side"]
        stats = {"loss_dj": self._joint_critic_step(x, z), "loss_g": 0.0, "cycle": 0.0}
        for _ in range(self.gen_steps):
            stats["loss_g"] += self._joint_generator_step(x, z) / self.gen_steps
            cycle = self.cycle_weight * (least_squares(de(en(x)) - x, 0.0) + least_squares(en(de(z)) - z, 0.0))
            stats["cycle"] += step(self.optims["cycle"], cycle) / self.gen_steps
        with torch.no_grad():
            gz = de(z)
        side = self.side_weight * 0.5 * (least_squares(dx(x), 1.0) + least_squares(dx(gz), 0.0))
        stats["loss_dx"] = step(self.optims["data_side"], side)
        with frozen(dx):
            stats["loss_de"] = step(self.optims["decoder_side"], self.side_weight * least_squares(dx(de(z)), 1.0))
        return stats
