"""BiGAN (Donahue, Krähenbühl & Darrell, ICLR 2017): the paper's learned baseline (§II.B).

Networks (baselines/nets.py, DCGAN-style for 64x64 maps): encoder En (the descriptor), decoder
De, joint discriminator D(x, z) on (x, En(x)) ("real") versus (De(z), z) ("fake").

Objective, Eq. 1 (the JSD value function), with BCE-with-logits:

* D maximises log D(x, En(x)) + log(1 - D(De(z), z)):
  L_D = BCE(D(x, En(x)), 1) + BCE(D(De(z), z), 0);
* En and De use the usual non-saturating form, i.e. the same loss with the labels swapped, as
  in Donahue et al.'s released code: L_EG = BCE(D(x, En(x)), 0) + BCE(D(De(z), z), 1).

One discriminator step then one encoder/decoder step per batch; Adam, lr 2e-4, betas (0.5,
0.999) for all (DCGAN's and BiGAN's defaults). P_z: uniform on [-1, 1]^d (BiGAN's choice),
`prior="normal"` for N(0, I). Dropout 0.2 in the joint discriminator's MLP (as BiGAN's).
Code size 1024 float32 (the paper's size for its learned descriptors). Encoder convolutions
16-32-64-128 (`encoder_width`, sized for 3 ms per frame on a 2-core CPU), decoder and
discriminator 32-64-128-256 (`width`), the same networks as Stable-AFL's.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn

from baselines.nets import Decoder, Encoder, JointCritic, init_weights
from safl_bench.methods.method import register_method
from safl_bench.methods.training import AdversarialMethod


def bce(logits: torch.Tensor, target: float) -> torch.Tensor:
    """Binary cross-entropy with logits against a constant label."""
    return F.binary_cross_entropy_with_logits(logits, torch.full_like(logits, target))


@register_method
class BiGAN(AdversarialMethod):
    """BiGAN encoder features (Donahue et al.), JSD joint discriminator (paper Eq. 1)."""

    name = "bigan"
    version = "1"

    def __init__(
        self,
        code_size: int = 1024,
        image_size: int = 64,
        width: int = 32,
        encoder_width: int = 16,
        hidden: int = 512,
        dropout: float = 0.2,
        prior: str = "uniform",
        lr: float = 2e-4,
        beta1: float = 0.5,
        epochs: int = 20,
        batch_size: int = 64,
        seed: int = 0,
        describe_batch: int = 256,
        device: str = "cpu",
    ):
        self.code_size = code_size
        self.image_size = image_size
        self.width = width
        self.encoder_width = encoder_width
        self.hidden = hidden
        self.dropout = dropout
        self.prior = prior
        self.lr = lr
        self.beta1 = beta1
        self.epochs = epochs
        self.batch_size = batch_size
        self.seed = seed
        self.describe_batch = describe_batch
        self.device = device
        self._init_networks()

    def build_networks(self) -> dict[str, nn.Module]:
        nets: dict[str, nn.Module] = {
            "encoder": Encoder(self.image_size, self.code_size, self.encoder_width),
            "decoder": Decoder(self.image_size, self.code_size, self.width),
            "joint": JointCritic(self.image_size, self.code_size, self.width, self.hidden, self.dropout),
        }
        for net in nets.values():
            init_weights(net)
        return nets

    @property
    def input_size(self) -> int:
        """The networks take `image_size` x `image_size` maps."""
        return self.image_size

    def build_optimizers(self) -> dict[str, torch.optim.Optimizer]:
        betas = (self.beta1, 0.999)
        gen_params = [*self.nets["encoder"].parameters(), *self.nets["decoder"].parameters()]
        return {
            "joint": torch.optim.Adam(self.nets["joint"].parameters(), lr=self.lr, betas=betas),
            "generator": torch.optim.Adam(gen_params, lr=self.lr, betas=betas),
        }

    def train_step(self, batches: Sequence[torch.Tensor], gen: torch.Generator) -> dict[str, float]:
        assert self.optims is not None
        x = batches[0]
        en, de, d = self.nets["encoder"], self.nets["decoder"], self.nets["joint"]
        z = self.sample_prior(len(x), gen)

        ez, gx = en(x), de(z)
        loss_d = bce(d(x, ez.detach()), 1.0) + bce(d(gx.detach(), z), 0.0)
        self.optims["joint"].zero_grad(set_to_none=True)
        loss_d.backward()
        self.optims["joint"].step()

        loss_g = bce(d(x, ez), 0.0) + bce(d(gx, z), 1.0)
        self.optims["generator"].zero_grad(set_to_none=True)
        loss_g.backward()
        self.optims["generator"].step()
        return {"loss_d": float(loss_d.detach()), "loss_g": float(loss_g.detach())}
