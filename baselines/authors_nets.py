"""The networks of the authors' paper-era code (CNN-GAN/Top-Mapping at commit 25be0fd,
2017-10-17, `src/module/module.py`), for `stable_afl@2` and `bigan@2`.

Every value below is read from that file (lines at 25be0fd) and `parameters.py` there:

* `AuthorsEncoder` (`encoder`, module.py:156-190): four 5x5 stride-2 'SAME' convolutions with
  `img_filter` = 64 base channels (parameters.py:40), 64-128-256-512, each followed by batch norm
  and LeakyReLU(0.2) (the first one too), flattened (4x4x512 for 64x64 maps) and a linear layer to
  the `code_dim` = 512-d code (parameters.py:22), no activation.
* `AuthorsDecoder` (`decoder`, :116-153): linear code -> 4x4x512, batch norm + ReLU, then 5x5
  stride-2 transposed convolutions 256-128-64 with batch norm + ReLU and a last one to the image,
  tanh.
* `AuthorsImageCritic` (`discriminator_X`, :231-269): the encoder's convolution trunk, then a
  linear layer to `dX_dim` = 1024 outputs (parameters.py:41) with batch norm and LeakyReLU(0.2):
  the critic's output is that 1024-d vector (its least-squares loss averages over it).
* `AuthorsJointCritic` (`discriminator_J`, :297-365): the same image trunk to 1024; a code path
  of dropout, linear 1024, dropout, linear 1024 (`dZ_dim`, parameters.py:42; no activations);
  the two concatenated, then
  dropout, linear 2048 + LeakyReLU(0.2), dropout, linear 2048 + LeakyReLU(0.2), dropout, linear 1
  + LeakyReLU(0.2) (`dJ_dim` = 2048, parameters.py:43). Dropout keeps 0.8 (`keep=0.8`,
  module.py:336-359), and is on in every training step (`feed_datas`, model.py:174-181, feeds
  `all_drop` for both methods).

Padding: TensorFlow's 'SAME' for a 5x5 stride-2 convolution of an even size pads 1 before and 2
after; the transposed convolution is its adjoint, which crops 1 before and 2 after. Both are
written so here (`_same_conv`, `_same_deconv`), not as PyTorch's symmetric padding, which would
shift every feature map by half a pixel against theirs.

Initialisation (module.py `w_init`, `gamma_init`, e.g. :158-159): weights N(0, 0.02), biases 0
(tensorlayer's default `b_init`), batch-norm scale N(1, 0.02), shift 0; batch-norm epsilon 1e-5
(tensorlayer's `BatchNormLayer` default).

Depth: at the authors' 64x64 (`output_size`, parameters.py:21) the networks have their four
stride-2 levels; another `image_size` (a power of two, e.g. the tests' 16) gets as many levels as
reach 4x4, so it is a smaller network of the same design, not theirs.

Batch norm at test time: the authors' test graph is the training graph (`is_train=True`,
model.py:67) fed one map at a time (model.py:364-373, with `batch_size` 1: the placeholder of
model.py:62-63 has that size), so each map is normalised with its own
statistics over its feature map, never with running averages. `test_stats="image"` (the
default) does that for a whole batch at once (instance normalisation with the batch norm's scale
and shift: the same numbers as batch 1); `test_stats="running"` uses the running averages, the
usual inference of batch norm.

One deviation: their maps are read as 3-channel JPEGs (`img_dim` = 3, parameters.py:20;
`is_grayscale=0`, model.py:364-365, src/data/__init__.py:21-22) of grey top views; ours are one
channel. A 3-channel copy of a grey map through a first convolution is a 1-channel convolution
with the three kernels summed, so the encoder and the critics are the same function class; only
their first layer's initial scale differs (sqrt(3)). The decoder's last layer writes one channel
where theirs writes three (module.py:148-149), which could also draw colour.
"""

from __future__ import annotations

import itertools

import torch
import torch.nn.functional as F
from torch import nn

from baselines.nets import levels
from safl_bench.errors import ConfigError

TEST_STATS = ("image", "running")
BN_EPS = 1e-5
KEEP = 0.8


class _SameConv(nn.Module):
    """5x5 stride-2 convolution with TensorFlow's 'SAME' padding (1 before, 2 after)."""

    def __init__(self, c_in: int, c_out: int):
        super().__init__()
        self.conv = nn.Conv2d(c_in, c_out, 5, 2, 0)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv(F.pad(x, (1, 2, 1, 2)))


class _SameDeconv(nn.Module):
    """5x5 stride-2 transposed convolution, the adjoint of `_SameConv` (crops 1 before, 2 after)."""

    def __init__(self, c_in: int, c_out: int):
        super().__init__()
        self.deconv = nn.ConvTranspose2d(c_in, c_out, 5, 2, 0)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.deconv(x)[..., 1:-2, 1:-2]


class _Trunk(nn.Module):
    """Conv (5x5, stride 2) + batch norm + LeakyReLU(0.2), four times: (N,1,S,S) -> (N, 8w, 4, 4).

    With `test_stats="image"`, a trunk in eval mode normalises each map with its own statistics
    (the authors' batch-1 test graph); in training mode it is ordinary batch norm."""

    def __init__(self, image_size: int, width: int, test_stats: str = "image"):
        super().__init__()
        if test_stats not in TEST_STATS:
            raise ConfigError(f"test_stats must be one of {TEST_STATS}, got {test_stats!r}")
        self.test_stats = test_stats
        channels = [1] + [width * 2**i for i in range(levels(image_size))]
        self.convs = nn.ModuleList(_SameConv(a, b) for a, b in itertools.pairwise(channels))
        self.norms: list[nn.BatchNorm2d] = nn.ModuleList(  # type: ignore[assignment]
            nn.BatchNorm2d(c, eps=BN_EPS) for c in channels[1:])
        self.channels = channels[-1]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        per_image = not self.training and self.test_stats == "image"
        for conv, norm in zip(self.convs, self.norms, strict=True):
            x = conv(x)
            if per_image:
                x = F.instance_norm(x, weight=norm.weight, bias=norm.bias, eps=norm.eps)
            else:
                x = norm(x)
            x = F.leaky_relu(x, 0.2)
        return x


class AuthorsEncoder(nn.Module):
    """En: (N,1,S,S) in [-1,1] -> (N, code_size), module.py:156-190 at 25be0fd."""

    def __init__(self, image_size: int = 64, code_size: int = 512, width: int = 64, test_stats: str = "image"):
        super().__init__()
        self.trunk = _Trunk(image_size, width, test_stats)
        self.head = nn.Linear(self.trunk.channels * 16, code_size)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.trunk(x).flatten(1))


class AuthorsDecoder(nn.Module):
    """De: (N, code_size) -> (N,1,S,S) in [-1,1], module.py:116-153 at 25be0fd."""

    def __init__(self, image_size: int = 64, code_size: int = 512, width: int = 64):
        super().__init__()
        depth = levels(image_size)
        self.channels = width * 2 ** (depth - 1)
        self.head = nn.Linear(code_size, self.channels * 16)
        layers: list[nn.Module] = [nn.BatchNorm2d(self.channels, eps=BN_EPS), nn.ReLU()]
        c = self.channels
        for _ in range(depth - 1):
            layers += [_SameDeconv(c, c // 2), nn.BatchNorm2d(c // 2, eps=BN_EPS), nn.ReLU()]
            c //= 2
        layers += [_SameDeconv(c, 1), nn.Tanh()]
        self.net = nn.Sequential(*layers)

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        return self.net(self.head(z).view(-1, self.channels, 4, 4))


class _ImageHead(nn.Module):
    """The image trunk, then linear to `out` features + batch norm + LeakyReLU(0.2)."""

    def __init__(self, image_size: int, width: int, out: int):
        super().__init__()
        self.trunk = _Trunk(image_size, width, "running")
        self.linear = nn.Linear(self.trunk.channels * 16, out)
        self.norm = nn.BatchNorm1d(out, eps=BN_EPS)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.leaky_relu(self.norm(self.linear(self.trunk(x).flatten(1))), 0.2)


class AuthorsImageCritic(nn.Module):
    """D_X: (N,1,S,S) -> (N, 1024), module.py:231-269 at 25be0fd."""

    def __init__(self, image_size: int = 64, width: int = 64, out: int = 1024):
        super().__init__()
        self.net = _ImageHead(image_size, width, out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


class AuthorsJointCritic(nn.Module):
    """D_J(x, z): one value per pair, module.py:297-365 at 25be0fd."""

    def __init__(self, image_size: int = 64, code_size: int = 512, width: int = 64,
                 x_dim: int = 1024, z_dim: int = 1024, joint_dim: int = 2048):
        super().__init__()
        drop = 1.0 - KEEP
        self.x_net = _ImageHead(image_size, width, x_dim)
        self.z_net = nn.Sequential(nn.Dropout(drop), nn.Linear(code_size, z_dim), nn.Dropout(drop),
                                   nn.Linear(z_dim, z_dim))
        self.joint = nn.Sequential(
            nn.Dropout(drop), nn.Linear(x_dim + z_dim, joint_dim), nn.LeakyReLU(0.2),
            nn.Dropout(drop), nn.Linear(joint_dim, joint_dim), nn.LeakyReLU(0.2),
            nn.Dropout(drop), nn.Linear(joint_dim, 1), nn.LeakyReLU(0.2),
        )

    def forward(self, x: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        return self.joint(torch.cat([self.x_net(x), self.z_net(z)], dim=1)).squeeze(1)


def init_authors(module: nn.Module) -> None:
    """module.py's `w_init` N(0, 0.02) and `gamma_init` N(1, 0.02); biases and shifts 0."""
    for m in module.modules():
        if isinstance(m, nn.Conv2d | nn.ConvTranspose2d | nn.Linear):
            nn.init.normal_(m.weight, 0.0, 0.02)
            if m.bias is not None:
                nn.init.zeros_(m.bias)
        elif isinstance(m, nn.BatchNorm2d | nn.BatchNorm1d):
            nn.init.normal_(m.weight, 1.0, 0.02)
            nn.init.zeros_(m.bias)


def least_squares(out: torch.Tensor, target: float) -> torch.Tensor:
    """module.py:373-374 `mae_criterion` (despite its name, the mean squared error)."""
    return ((out - target) ** 2).mean()
