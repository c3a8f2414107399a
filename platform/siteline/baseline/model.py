"""FC-Siam-diff (Daudt, Le Saux, Boulch, ICIP 2018): a siamese U-Net whose skip connections carry the
absolute difference of the two encodings. Encoder 16-32-64-128, about 1.35M parameters."""

from __future__ import annotations

import torch
from torch import nn


def _block(cin: int, cout: int, n: int) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(n):
        layers += [
            nn.Conv2d(cin if i == 0 else cout, cout, 3, padding=1),
            nn.BatchNorm2d(cout),
            nn.ReLU(inplace=True),
            nn.Dropout2d(0.2),
        ]
    return nn.Sequential(*layers)


def _up_block(cin: int, cmid: int, cout: int, n: int, last: bool = False) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(n):
        a = cin if i == 0 else cmid
        b = cout if i == n - 1 else cmid
        layers.append(nn.ConvTranspose2d(a, b, 3, padding=1))
        if not (last and i == n - 1):
            layers += [nn.BatchNorm2d(b), nn.ReLU(inplace=True), nn.Dropout2d(0.2)]
    return nn.Sequential(*layers)


class FCSiamDiff(nn.Module):
    """Input (B, 2, 3, H, W) float in [0, 1] (H, W multiples of 16); output logits (B, 2, H, W)."""

    def __init__(self, in_channels: int = 3, classes: int = 2) -> None:
        super().__init__()
        self.enc = nn.ModuleList(
            [_block(in_channels, 16, 2), _block(16, 32, 2), _block(32, 64, 3), _block(64, 128, 3)]
        )
        self.pool = nn.MaxPool2d(2)
        self.up = nn.ModuleList(
            [nn.ConvTranspose2d(c, c, 3, stride=2, padding=1, output_padding=1) for c in (128, 64, 32, 16)]
        )
        self.dec = nn.ModuleList(
            [
                _up_block(256, 128, 64, 3),
                _up_block(128, 64, 32, 3),
                _up_block(64, 32, 16, 2),
                _up_block(32, 16, classes, 2, last=True),
            ]
        )

    def _encode(self, x: torch.Tensor) -> tuple[list[torch.Tensor], torch.Tensor]:
        skips = []
        for block in self.enc:
            x = block(x)
            skips.append(x)
            x = self.pool(x)
        return skips, x

    def forward(self, pair: torch.Tensor) -> torch.Tensor:
        s1, _ = self._encode(pair[:, 0])
        s2, x = self._encode(pair[:, 1])
        for i, (up, dec) in enumerate(zip(self.up, self.dec, strict=True)):
            x = up(x)
            k = 3 - i
            diff = (s1[k] - s2[k]).abs()
            x = x[..., : diff.shape[-2], : diff.shape[-1]]
            x = dec(torch.cat([x, diff], dim=1))
        return x


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
