"""Joint augmentations of a change-detection sample (the paper's: flips, colour jitter, crops; no
rotation, which would turn cranes upside down)."""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class TrainTransforms:
    """Random crop to ``crop`` pixels (padding the mask with 255 when the image is smaller), horizontal
    and vertical flips (p=0.5 each, same for both images and the mask), and per-image brightness /
    contrast jitter of +-``jitter``. ``generator`` makes it reproducible."""

    crop: int = 256
    jitter: float = 0.2
    generator: torch.Generator | None = None

    def _rand(self) -> float:
        return float(torch.rand((), generator=self.generator))

    def __call__(self, sample: dict) -> dict:
        img, mask = sample["image"], sample["mask"]
        _, _, h, w = img.shape
        if h < self.crop or w < self.crop:
            ph, pw = max(0, self.crop - h), max(0, self.crop - w)
            img = torch.nn.functional.pad(img, (0, pw, 0, ph))
            mask = torch.nn.functional.pad(mask, (0, pw, 0, ph), value=255)
            h, w = img.shape[-2:]
        top = int(self._rand() * (h - self.crop + 1))
        left = int(self._rand() * (w - self.crop + 1))
        img = img[..., top : top + self.crop, left : left + self.crop]
        mask = mask[..., top : top + self.crop, left : left + self.crop]
        if self._rand() < 0.5:
            img, mask = img.flip(-1), mask.flip(-1)
        if self._rand() < 0.5:
            img, mask = img.flip(-2), mask.flip(-2)
        out = []
        for t in range(img.shape[0]):
            b = 1.0 + (self._rand() * 2 - 1) * self.jitter
            c = 1.0 + (self._rand() * 2 - 1) * self.jitter
            x = img[t] * b
            mean = x.mean()
            out.append(((x - mean) * c + mean).clamp(0, 1))
        return {**sample, "image": torch.stack(out), "mask": mask}
