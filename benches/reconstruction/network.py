"""A small E2VID-like recurrent U-Net (Rebecq et al., TPAMI 2019; Scheerlinck et al.'s
FireNet, WACV 2020, for the size): a voxel grid in, an intensity image in [0, 1] out, a
convolutional GRU (Ballas et al., ICLR 2016) at the bottleneck carrying the state from one
window to the next. Two stride-2 encoders, so height and width must be multiples of 4
(`padded_size`). Small enough to train on 2 CPU cores in minutes."""

from __future__ import annotations

import torch
from torch import nn

DOWNSAMPLING = 4


def padded_size(height: int, width: int) -> tuple[int, int]:
    """The next multiple of 4 of each side (the input is zero-padded: no events there)."""
    return -(-height // DOWNSAMPLING) * DOWNSAMPLING, -(-width // DOWNSAMPLING) * DOWNSAMPLING


class ConvGRU(nn.Module):
    """h' = (1 - z) h + z tanh(W [x, r h]), z, r = sigmoid(W [x, h]) (Ballas et al. 2016)."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.gates = nn.Conv2d(2 * channels, 2 * channels, 3, padding=1)
        self.candidate = nn.Conv2d(2 * channels, channels, 3, padding=1)

    def forward(self, x: torch.Tensor, state: torch.Tensor | None) -> torch.Tensor:
        h = torch.zeros_like(x) if state is None else state
        z, r = torch.sigmoid(self.gates(torch.cat([x, h], 1))).chunk(2, 1)
        candidate = torch.tanh(self.candidate(torch.cat([x, r * h], 1)))
        return (1 - z) * h + z * candidate


def _block(channels_in: int, channels_out: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(channels_in, channels_out, 3, stride=stride, padding=1), nn.ReLU(inplace=True)
    )


class RecurrentUNet(nn.Module):
    """head (C) -> down (2C, /2) -> down (4C, /4) -> ConvGRU -> up (2C) + skip -> up (C) + skip
    -> sigmoid image."""

    def __init__(self, bins: int = 5, channels: int = 16) -> None:
        super().__init__()
        c = channels
        self.head = _block(bins, c)
        self.down1 = _block(c, 2 * c, stride=2)
        self.down2 = _block(2 * c, 4 * c, stride=2)
        self.memory = ConvGRU(4 * c)
        self.up2 = _block(4 * c + 2 * c, 2 * c)
        self.up1 = _block(2 * c + c, c)
        self.out = nn.Conv2d(c, 1, 1)

    def forward(
        self, voxels: torch.Tensor, state: torch.Tensor | None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, bins, H, W) -> image (N, 1, H, W), new state."""
        s1 = self.head(voxels)
        s2 = self.down1(s1)
        state = self.memory(self.down2(s2), state)
        u2 = nn.functional.interpolate(state, scale_factor=2.0, mode="bilinear")
        u2 = self.up2(torch.cat([u2, s2], 1))
        u1 = nn.functional.interpolate(u2, scale_factor=2.0, mode="bilinear")
        u1 = self.up1(torch.cat([u1, s1], 1))
        return torch.sigmoid(self.out(u1)), state


def ssim_loss(image: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """1 - SSIM with the 11 px, sigma 1.5 Gaussian window (the benchmark's metric, in torch)."""
    offsets = torch.arange(11, dtype=image.dtype) - 5.0
    line = torch.exp(-(offsets**2) / (2 * 1.5**2))
    window = (line[:, None] * line[None, :] / line.sum() ** 2)[None, None]

    def mean(values: torch.Tensor) -> torch.Tensor:
        return nn.functional.conv2d(values, window)

    mu_x, mu_y = mean(image), mean(target)
    var_x = mean(image * image) - mu_x**2
    var_y = mean(target * target) - mu_y**2
    cov = mean(image * target) - mu_x * mu_y
    c1, c2 = 0.01**2, 0.03**2
    index = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / (
        (mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2)
    )
    return 1.0 - index.mean()
