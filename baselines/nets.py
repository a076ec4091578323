"""DCGAN-style networks for square top-view maps (64x64 by default), shared by BiGAN and
Stable-AFL.

All image tensors are (N, 1, S, S) in [-1, 1] (maps in [0, 1] are mapped by 2x - 1); codes are
(N, code_size). With `width` w the feature maps go S -> S/2 ... -> 4 with w, 2w, 4w, 8w, ...
channels (for S = 64: 32-64-128-256 at w = 32), as in Radford et al.'s DCGAN:

* `Encoder`: strided 4x4 convolutions, batch norm after all but the first, LeakyReLU(0.2), then a
  linear layer from the 4x4 feature map to the code (DCGAN's 4x4 valid convolution written as a
  matrix product, which is 7x faster on a CPU at batch 1; linear output: the code is the
  descriptor).
* `Decoder`: the mirror image: a linear layer to 4x4 feature maps, transposed convolutions,
  batch norm + ReLU, tanh output.
* `JointCritic` D(x, z): a conv trunk on x, an MLP on z, an MLP on both (BiGAN's joint
  discriminator). One logit / critic value per pair. No batch norm (WGAN weight clipping and the
  JSD loss both work without it, and a critic's value then does not depend on its batch).
* `ImageCritic` D_X(x) and `CodeCritic` D_Z(z): the side discriminators of Stable-AFL.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from safl_bench.errors import ConfigError


def levels(image_size: int) -> int:
    """Number of stride-2 stages from image_size down to 4x4."""
    n = round(math.log2(image_size / 4)) if image_size >= 8 else 0
    if n < 1 or 4 * 2**n != image_size:
        raise ConfigError(f"image_size must be a power of two >= 8, got {image_size!r}")
    return n


def _trunk(image_size: int, width: int, batch_norm: bool) -> tuple[nn.Sequential, int]:
    """Strided conv stack (N,1,S,S) -> (N, C, 4, 4); returns it and C."""
    layers: list[nn.Module] = []
    c_in, c_out = 1, width
    for i in range(levels(image_size)):
        layers.append(nn.Conv2d(c_in, c_out, 4, 2, 1, bias=not (batch_norm and i > 0)))
        if batch_norm and i > 0:
            layers.append(nn.BatchNorm2d(c_out))
        layers.append(nn.LeakyReLU(0.2, inplace=True))
        c_in, c_out = c_out, c_out * 2
    return nn.Sequential(*layers), c_in


class Encoder(nn.Module):
    """En: map (N,1,S,S) in [-1,1] -> code (N, code_size)."""

    def __init__(self, image_size: int = 64, code_size: int = 1024, width: int = 32):
        super().__init__()
        self.trunk, channels = _trunk(image_size, width, batch_norm=True)
        self.head = nn.Linear(channels * 16, code_size)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.trunk(x).flatten(1))


class Decoder(nn.Module):
    """De: code (N, code_size) -> map (N,1,S,S) in [-1,1]."""

    def __init__(self, image_size: int = 64, code_size: int = 1024, width: int = 32):
        super().__init__()
        depth = levels(image_size)
        channels = width * 2 ** (depth - 1)
        self.channels = channels
        self.head = nn.Linear(code_size, channels * 16, bias=False)
        layers: list[nn.Module] = [nn.BatchNorm2d(channels), nn.ReLU(inplace=True)]
        for _ in range(depth - 1):
            layers += [
                nn.ConvTranspose2d(channels, channels // 2, 4, 2, 1, bias=False),
                nn.BatchNorm2d(channels // 2),
                nn.ReLU(inplace=True),
            ]
            channels //= 2
        layers += [nn.ConvTranspose2d(channels, 1, 4, 2, 1), nn.Tanh()]
        self.net = nn.Sequential(*layers)

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        return self.net(self.head(z).view(-1, self.channels, 4, 4))


class JointCritic(nn.Module):
    """D_J(x, z): one value per (map, code) pair (a logit for JSD/LSGAN, a critic for WGAN)."""

    def __init__(self, image_size: int = 64, code_size: int = 1024, width: int = 32, hidden: int = 512, dropout: float = 0.0):
        super().__init__()
        self.x_net, channels = _trunk(image_size, width, batch_norm=False)
        self.z_net = nn.Sequential(
            nn.Linear(code_size, hidden), nn.LeakyReLU(0.2, inplace=True),
            nn.Linear(hidden, hidden), nn.LeakyReLU(0.2, inplace=True),
        )
        self.joint = nn.Sequential(
            nn.Dropout(dropout),
            nn.Linear(channels * 16 + hidden, hidden), nn.LeakyReLU(0.2, inplace=True),
            nn.Dropout(dropout),
            nn.Linear(hidden, 1),
        )

    def forward(self, x: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        return self.joint(torch.cat([self.x_net(x).flatten(1), self.z_net(z)], dim=1)).squeeze(1)


class ImageCritic(nn.Module):
    """D_X(x): the data-domain side discriminator (DCGAN discriminator without batch norm)."""

    def __init__(self, image_size: int = 64, width: int = 32):
        super().__init__()
        self.trunk, channels = _trunk(image_size, width, batch_norm=False)
        self.head = nn.Conv2d(channels, 1, 4, 1, 0)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.trunk(x)).flatten()


class CodeCritic(nn.Module):
    """D_Z(z): the code-domain side discriminator (an MLP)."""

    def __init__(self, code_size: int = 1024, hidden: int = 512):
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(code_size, hidden), nn.LeakyReLU(0.2, inplace=True),
            nn.Linear(hidden, hidden), nn.LeakyReLU(0.2, inplace=True),
            nn.Linear(hidden, 1),
        )

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        return self.net(z).squeeze(1)


def init_weights(module: nn.Module) -> None:
    """DCGAN initialisation: conv/linear weights N(0, 0.02), batch-norm scale N(1, 0.02)."""
    for m in module.modules():
        if isinstance(m, nn.Conv2d | nn.ConvTranspose2d | nn.Linear):
            nn.init.normal_(m.weight, 0.0, 0.02)
            if m.bias is not None:
                nn.init.zeros_(m.bias)
        elif isinstance(m, nn.BatchNorm2d):
            nn.init.normal_(m.weight, 1.0, 0.02)
            nn.init.zeros_(m.bias)
