"""Stable-AFL: stable adversarial feature learning (the paper's §III), a BiGAN made stable.

Networks (baselines/nets.py, DCGAN-style, shared with BiGAN): encoder En (the descriptor),
decoder De, joint critic D_J(x, z), data-domain side discriminator D_X(x) and code-domain side
discriminator D_Z(z).

Losses, with x ~ P_data (top-view maps scaled to [-1, 1]) and z ~ P_z:

* L_J, Eq. 9, the Wasserstein joint loss: D_J maximises E[D_J(x, En(x))] - E[D_J(De(z), z)]
  under a Lipschitz constraint enforced as in WGAN by clipping every D_J weight to
  [-`clip`, `clip`] = [-0.01, 0.01] after each critic step; En and De minimise the same
  quantity. `critic_steps` = 5 critic steps (each on a fresh batch) per En/De step, RMSprop with
  lr `critic_lr` = 5e-5 (WGAN's published defaults; the paper gives none).
* L_CYC, Eq. 10, cycle reconstruction in both domains with L2 losses:
  E_x ||De(En(x)) - x||^2 + E_z ||En(De(z)) - z||^2. The paper prints the compositions the
  wrong way round (En(De(x)) - x and De(En(z)) - z, which do not type-check: En takes maps, De
  takes codes); we implement the intended ones. ||.||^2 is the squared L2 norm per sample,
  as printed (`cycle_norm="sum"`, averaged over the batch); weight `cycle_weight` = 1 as in
  Eq. 12. `cycle_norm="mean"` (the mean over elements, torch's MSE) weighs the cycle terms
  4096x (maps) and 1024x (codes) less; with it the Wasserstein term dominated, the decoder
  learned the mean map and the encoder did not beat its random initialisation on the
  benchmark (measured on the synthetic default; see the README).
* L_X, Eq. 11, the side data-domain GAN with the original JSD loss: D_X maximises
  log D_X(x) + log(1 - D_X(De(z))); De minimises it in the usual non-saturating form
  (BCE(D_X(De(z)), 1)), as in Goodfellow et al. and DCGAN.
* L_Z: Eq. 12 lists L_Z and D_Z but the paper never defines them. We take the symmetric
  counterpart of Eq. 11 in the code domain, as in the authors' public code: D_Z tells prior
  samples z ~ P_z from codes En(x) (JSD loss), and En is trained to make En(x) look like a
  sample of P_z (non-saturating). `code_side=False` drops L_Z and D_Z.
* Full objective, Eq. 12: En and De minimise L_J + L_X + L_Z + cycle_weight * L_CYC;
  D_J, D_X, D_Z maximise their terms.

Network size: the encoder's convolutions have `encoder_width` = 16 base channels (16-32-64-128
for 64x64 maps, then a linear layer to the 1024-d code), sized for the issue's budget of 3 ms per
frame at batch 1 on a 2-core CPU (32-64-128-256 measured 3.6-5 ms there, single thread, on a
shared machine); the decoder and the critics, which are never timed, use `width` = 32
(32-64-128-256, DCGAN's shape at half its width).

Choices where the paper is silent: Adam, lr 2e-4, betas (0.5, 0.999) for En, De, D_X and D_Z
(DCGAN's/BiGAN's defaults); batch 16 (WGAN's 64, with 5 critic batches per En/De step, leaves
only 4 En/De steps per epoch of 1400 maps; 16 gives 17); P_z uniform on [-1, 1]^d (BiGAN's prior; `prior="normal"`
for N(0, I)); code 1024-d float32 (the paper, §IV.D). Side discriminators are updated once per
En/De step. WGAN's schedule of 100 critic steps during the first 25 generator steps is not used.

The authors' public code differs from the paper; its choices are options:
`code_size=512`, `joint_loss="lsgan"` (least squares: D_J regresses real pairs to 1 and fake
pairs to 0, En/De the swapped targets; Adam like the rest, no clipping), and
`side_loss="wasserstein"` (D_X and D_Z as clipped Wasserstein critics trained with RMSprop
inside the critic loop). `joint_loss="jsd"` gives BiGAN's joint loss plus the other terms.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn

from baselines.bigan import bce
from baselines.nets import CodeCritic, Decoder, Encoder, ImageCritic, JointCritic, init_weights
from safl_bench.errors import ConfigError
from safl_bench.methods.method import register_method
from safl_bench.methods.training import AdversarialMethod

JOINT_LOSSES = ("wasserstein", "lsgan", "jsd")
SIDE_LOSSES = ("jsd", "wasserstein")
CYCLE_NORMS = ("sum", "mean")


def _squared_error(a: torch.Tensor, b: torch.Tensor, norm: str) -> torch.Tensor:
    """E ||a - b||^2: the squared L2 norm per sample ("sum", Eq. 10 as printed) or the mean
    squared error per element ("mean"), averaged over the batch."""
    if norm == "mean":
        return F.mse_loss(a, b)
    return (a - b).pow(2).flatten(1).sum(dim=1).mean()


def _critic_loss(kind: str, real: torch.Tensor, fake: torch.Tensor) -> torch.Tensor:
    """What a critic/discriminator minimises, given its outputs on real and fake samples."""
    if kind == "wasserstein":
        return fake.mean() - real.mean()
    if kind == "lsgan":
        return 0.5 * ((real - 1.0) ** 2).mean() + 0.5 * (fake**2).mean()
    return bce(real, 1.0) + bce(fake, 0.0)


def _generator_loss(kind: str, real: torch.Tensor | None, fake: torch.Tensor | None) -> torch.Tensor:
    """What En/De minimise against a critic: the swapped-label / negated critic objective.

    `real` are critic outputs on pairs built from data (x, En(x)), `fake` on pairs built from the
    prior; either may be None for the one-sided side losses."""
    terms = []
    if real is not None:
        terms.append(real.mean() if kind == "wasserstein" else
                     0.5 * (real**2).mean() if kind == "lsgan" else bce(real, 0.0))
    if fake is not None:
        terms.append(-fake.mean() if kind == "wasserstein" else
                     0.5 * ((fake - 1.0) ** 2).mean() if kind == "lsgan" else bce(fake, 1.0))
    return torch.stack(terms).sum()


def _clip(net: nn.Module, bound: float) -> None:
    with torch.no_grad():
        for p in net.parameters():
            p.clamp_(-bound, bound)


@register_method
class StableAFL(AdversarialMethod):
    """Stable-AFL (the paper): BiGAN + Wasserstein joint critic + cycle losses + side GANs."""

    name = "stable_afl"
    version = "1"

    def __init__(
        self,
        code_size: int = 1024,
        image_size: int = 64,
        width: int = 32,
        encoder_width: int = 16,
        hidden: int = 512,
        prior: str = "uniform",
        joint_loss: str = "wasserstein",
        side_loss: str = "jsd",
        code_side: bool = True,
        cycle_weight: float = 1.0,
        cycle_norm: str = "sum",
        clip: float = 0.01,
        critic_steps: int = 5,
        critic_lr: float = 5e-5,
        lr: float = 2e-4,
        beta1: float = 0.5,
        epochs: int = 20,
        batch_size: int = 16,
        seed: int = 0,
        describe_batch: int = 256,
        device: str = "cpu",
    ):
        self.code_size = code_size
        self.image_size = image_size
        self.width = width
        self.encoder_width = encoder_width
        self.hidden = hidden
        self.prior = prior
        self.joint_loss = joint_loss
        self.side_loss = side_loss
        self.code_side = code_side
        self.cycle_weight = cycle_weight
        self.cycle_norm = cycle_norm
        self.clip = clip
        self.critic_steps = critic_steps
        self.critic_lr = critic_lr
        self.lr = lr
        self.beta1 = beta1
        self.epochs = epochs
        self.batch_size = batch_size
        self.seed = seed
        self.describe_batch = describe_batch
        self.device = device
        if cycle_norm not in CYCLE_NORMS:
            raise ConfigError(f"stable_afl: cycle_norm must be one of {CYCLE_NORMS}, got {cycle_norm!r}")
        if joint_loss not in JOINT_LOSSES:
            raise ConfigError(f"stable_afl: joint_loss must be one of {JOINT_LOSSES}, got {joint_loss!r}")
        if side_loss not in SIDE_LOSSES:
            raise ConfigError(f"stable_afl: side_loss must be one of {SIDE_LOSSES}, got {side_loss!r}")
        if not isinstance(critic_steps, int) or critic_steps < 1:
            raise ConfigError(f"stable_afl: critic_steps must be a positive integer, got {critic_steps!r}")
        if not clip > 0:
            raise ConfigError(f"stable_afl: clip must be > 0, got {clip!r}")
        self._init_networks()

    @property
    def batches_per_step(self) -> int:
        return self.critic_steps

    @property
    def input_size(self) -> int:
        """The networks take `image_size` x `image_size` maps."""
        return self.image_size

    def _side_nets(self) -> list[str]:
        return ["data_side"] + (["code_side"] if self.code_side else [])

    def build_networks(self) -> dict[str, nn.Module]:
        nets: dict[str, nn.Module] = {
            "encoder": Encoder(self.image_size, self.code_size, self.encoder_width),
            "decoder": Decoder(self.image_size, self.code_size, self.width),
            "joint": JointCritic(self.image_size, self.code_size, self.width, self.hidden),
            "data_side": ImageCritic(self.image_size, self.width),
        }
        if self.code_side:
            nets["code_side"] = CodeCritic(self.code_size, self.hidden)
        for net in nets.values():
            init_weights(net)
        return nets

    def _critic_optimizer(self, kind: str, net: nn.Module) -> torch.optim.Optimizer:
        if kind == "wasserstein":
            return torch.optim.RMSprop(net.parameters(), lr=self.critic_lr)
        return torch.optim.Adam(net.parameters(), lr=self.lr, betas=(self.beta1, 0.999))

    def build_optimizers(self) -> dict[str, torch.optim.Optimizer]:
        gen_params = [*self.nets["encoder"].parameters(), *self.nets["decoder"].parameters()]
        optims = {
            "generator": torch.optim.Adam(gen_params, lr=self.lr, betas=(self.beta1, 0.999)),
            "joint": self._critic_optimizer(self.joint_loss, self.nets["joint"]),
        }
        for side in self._side_nets():
            optims[side] = self._critic_optimizer(self.side_loss, self.nets[side])
        return optims

    def _critic_update(self, name: str, kind: str, real: torch.Tensor, fake: torch.Tensor) -> float:
        assert self.optims is not None
        loss = _critic_loss(kind, real, fake)
        self.optims[name].zero_grad(set_to_none=True)
        loss.backward()
        self.optims[name].step()
        if kind == "wasserstein":
            _clip(self.nets[name], self.clip)
        return float(loss.detach())

    def _side_updates(self, x: torch.Tensor, gx: torch.Tensor, z: torch.Tensor, ez: torch.Tensor) -> dict[str, float]:
        out = {"loss_dx": self._critic_update("data_side", self.side_loss, self.nets["data_side"](x), self.nets["data_side"](gx))}
        if self.code_side:
            out["loss_dz"] = self._critic_update("code_side", self.side_loss, self.nets["code_side"](z), self.nets["code_side"](ez))
        return out

    def train_step(self, batches: Sequence[torch.Tensor], gen: torch.Generator) -> dict[str, float]:
        assert self.optims is not None
        en, de, dj = self.nets["encoder"], self.nets["decoder"], self.nets["joint"]
        stats: dict[str, float] = {"loss_dj": 0.0}
        side_in_loop = self.side_loss == "wasserstein"

        # critic iterations (Eq. 9 for D_J; Wasserstein side critics too when chosen)
        for x in batches:
            z = self.sample_prior(len(x), gen)
            with torch.no_grad():
                ez, gx = en(x), de(z)
            stats["loss_dj"] += self._critic_update("joint", self.joint_loss, dj(x, ez), dj(gx, z)) / len(batches)
            if side_in_loop:
                for k, v in self._side_updates(x, gx, z, ez).items():
                    stats[k] = stats.get(k, 0.0) + v / len(batches)

        # side discriminators (JSD, Eq. 11 and L_Z) and the En/De step (Eq. 12)
        x = batches[-1]
        z = self.sample_prior(len(x), gen)
        ez, gx = en(x), de(z)
        if not side_in_loop:
            stats.update(self._side_updates(x, gx.detach(), z, ez.detach()))

        loss_j = _generator_loss(self.joint_loss, dj(x, ez), dj(gx, z))
        loss_x = _generator_loss(self.side_loss, None, self.nets["data_side"](gx))
        loss_z = (_generator_loss(self.side_loss, None, self.nets["code_side"](ez))
                  if self.code_side else torch.zeros((), device=x.device))
        cyc_x = _squared_error(de(ez), x, self.cycle_norm)
        cyc_z = _squared_error(en(gx), z, self.cycle_norm)
        total = loss_j + loss_x + loss_z + self.cycle_weight * (cyc_x + cyc_z)
        self.optims["generator"].zero_grad(set_to_none=True)
        total.backward()
        self.optims["generator"].step()
        values = {"loss_j": loss_j, "loss_x": loss_x, "loss_z": loss_z, "cycle_x": cyc_x, "cycle_z": cyc_z, "loss_g": total}
        stats.update({k: float(v.detach()) for k, v in values.items()})
        return stats
