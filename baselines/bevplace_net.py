"""BEVPlace's network (Luo et al., ICCV 2023) as modules whose state-dict keys are the authors'.

The published checkpoint's 42 tensors load into `BevPlaceNet` strictly, by name:

* ``encoder.extractor.extractor.*``: `LocalCNN`, the per-copy feature extractor: four 5x5
  convolutions without bias (3 -> 16 -> 32, 2x2 average pooling, 32 -> 32 -> 32), each followed
  by instance normalisation (no affine part, biased variance, eps 1e-5) and all but the last by
  a ReLU; the output is L2-normalised over channels (norm clamped at 1e-6).
* ``encoder.embedder.embedder.*``: `GroupEmbedder`, two residual CNN branches over the 5 x 5
  grid of (scale, rotation) copies (3x3 convolutions with bias, zero padding), one ending in 8
  channels and one in 16; their bilinear product (8 x 25) @ (25 x 16) is the 128-d local
  feature, L2-normalised (clamp 1e-6). Pooling over the group makes it invariant to the
  transformations of the group, rotation above all.
* ``netvlad.*``: `NetVLAD` over the local features: 64 clusters, soft assignment by a 1x1
  convolution without bias and a softmax over clusters, residuals to the centroids summed over
  the points, intra-normalised per cluster, flattened (64 x 128 = 8192) and L2-normalised.
  ``netvlad.wq`` and ``netvlad.wk`` are in the checkpoint but the forward pass of the code that
  wrote it never uses them (they are kept here only so that loading stays strict).

This module holds the networks only; the transformed copies, the sampled points and the two
ways of running the networks (the plain port and the fast path) are in `baselines.bevplace`.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

#: Copies of the image per group: 5 scales x 5 rotations.
GROUP_SCALES = 5
GROUP_ROTATIONS = 5
LOCAL_DIM = 128
CLUSTERS = 64


def channel_l2_normalize(x: torch.Tensor, dim: int) -> torch.Tensor:
    """x / max(||x||, 1e-6) along `dim` (BEVPlace's normalisation of local features)."""
    return x / torch.linalg.vector_norm(x, dim=dim, keepdim=True).clamp_min(1e-6)


class LocalCNN(nn.Module):
    """The per-copy extractor: (B, 3, H, W) -> (B, 32, H // 2, W // 2), unit length per pixel."""

    def __init__(self) -> None:
        super().__init__()
        self.conv0 = nn.Sequential(
            nn.Conv2d(3, 16, 5, 1, 2, bias=False), nn.InstanceNorm2d(16), nn.ReLU(),
            nn.Conv2d(16, 32, 5, 1, 2, bias=False), nn.InstanceNorm2d(32), nn.ReLU(),
            nn.AvgPool2d(2, 2),
        )
        self.conv1 = nn.Sequential(
            nn.Conv2d(32, 32, 5, 1, 2, bias=False), nn.InstanceNorm2d(32), nn.ReLU(),
            nn.Conv2d(32, 32, 5, 1, 2, bias=False), nn.InstanceNorm2d(32),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return channel_l2_normalize(self.conv1(self.conv0(x)), dim=1)


class _ExtractorSlot(nn.Module):
    """Holds the extractor under the name the checkpoint uses (``extractor.extractor``)."""

    def __init__(self) -> None:
        super().__init__()
        self.extractor = LocalCNN()


def _block(c_in: int, c_mid: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_mid, 3, 1, 1), nn.ReLU(), nn.Conv2d(c_mid, c_out, 3, 1, 1))


class GroupEmbedder(nn.Module):
    """Group features (P, 32, 5, 5) (one per point: channels x scales x rotations) -> (P, 128)."""

    def __init__(self) -> None:
        super().__init__()
        for branch, last in ((1, 8), (2, 16)):
            setattr(self, f"network{branch}_embed1", _block(32, 64, 64))
            setattr(self, f"network{branch}_embed1_short", nn.Conv2d(32, 64, 1, 1))
            setattr(self, f"network{branch}_embed2", _block(64, 64, 64))
            setattr(self, f"network{branch}_embed2_short", nn.Conv2d(64, 64, 1, 1))
            setattr(self, f"network{branch}_embed3", _block(64, 64, last))

    def branch(self, x: torch.Tensor, index: int) -> torch.Tensor:
        """One residual branch: (P, 32, 5, 5) -> (P, 8 or 16, 5, 5)."""
        m = {name: getattr(self, f"network{index}_{name}")
             for name in ("embed1", "embed1_short", "embed2", "embed2_short", "embed3")}
        x = F.relu(m["embed1"](x) + m["embed1_short"](x))
        x = F.relu(m["embed2"](x) + m["embed2_short"](x))
        return m["embed3"](x)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        p = x.shape[0]
        left = self.branch(x, 1).reshape(p, 8, -1)
        right = self.branch(x, 2).reshape(p, 16, -1)
        return channel_l2_normalize(torch.bmm(left, right.transpose(1, 2)).reshape(p, LOCAL_DIM), dim=1)


class _EmbedderSlot(nn.Module):
    """Holds the embedder under the name the checkpoint uses (``embedder.embedder``)."""

    def __init__(self) -> None:
        super().__init__()
        self.embedder = GroupEmbedder()


class GroupEncoder(nn.Module):
    """Container of the extractor and the embedder (``encoder.*`` in the checkpoint)."""

    def __init__(self) -> None:
        super().__init__()
        self.extractor = _ExtractorSlot()
        self.embedder = _EmbedderSlot()


class NetVLAD(nn.Module):
    """NetVLAD over (B, 128, P) local features -> (B, 8192), unit length."""

    def __init__(self, clusters: int = CLUSTERS, dim: int = LOCAL_DIM) -> None:
        super().__init__()
        self.conv = nn.Conv2d(dim, clusters, kernel_size=1, bias=False)
        self.centroids = nn.Parameter(torch.rand(clusters, dim))
        # present in the published checkpoint, unused by its forward pass
        self.wq = nn.Linear(dim, 64)
        self.wk = nn.Linear(dim, 64)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The plain formulation: every residual x_p - c_k, weighted and summed over points."""
        b = x.shape[0]
        assign = F.softmax(self.conv(x[..., None])[..., 0], dim=1)  # (B, K, P)
        residuals = x[:, None, :, :] - self.centroids[None, :, :, None]  # (B, K, C, P)
        vlad = (residuals * assign[:, :, None, :]).sum(dim=-1)  # (B, K, C)
        vlad = F.normalize(vlad, p=2, dim=2)
        return F.normalize(vlad.reshape(b, -1), p=2, dim=1)

    def forward_fast(self, x: torch.Tensor) -> torch.Tensor:
        """The same as `forward` by matrix products: sum_p a_kp x_p - (sum_p a_kp) c_k."""
        b = x.shape[0]
        weight = self.conv.weight[:, :, 0, 0]
        assign = torch.softmax(torch.matmul(weight, x), dim=1)  # (B, K, P)
        vlad = torch.bmm(assign, x.transpose(1, 2)) - assign.sum(dim=2, keepdim=True) * self.centroids
        vlad = F.normalize(vlad, p=2, dim=2)
        return F.normalize(vlad.reshape(b, -1), p=2, dim=1)


class BevPlaceNet(nn.Module):
    """All of BEVPlace's learned state, keyed as in the authors' checkpoint."""

    def __init__(self) -> None:
        super().__init__()
        self.encoder = GroupEncoder()
        self.netvlad = NetVLAD()

    @property
    def local_cnn(self) -> LocalCNN:
        return self.encoder.extractor.extractor

    @property
    def group_embedder(self) -> GroupEmbedder:
        return self.encoder.embedder.embedder
