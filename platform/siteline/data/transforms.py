"""Joint augmentations of a change-detection sample (the paper's: flips, colour jitter, crops; no
rotation, which would turn cranes upside down)."""

from __future__ import annotations

from dataclasses import dataclass, field

import torch


@dataclass
class TrainTransforms:
    """Random crop to ``crop`` pixels (padding the mask with 255 when the image is smaller), horizontal
    and vertical flips (p=0.5 each, same for both images and the mask), and per-image brightness /
    contrast jitter of +-``jitter``. ``seed`` makes it reproducible; each DataLoader worker draws from
    its own stream (seed + worker id), so the object pickles into spawned workers."""

    crop: int = 256
    jitter: float = 0.2
    seed: int | None = None
    _generator: torch.Generator | None = field(default=None, init=False, repr=False)
    _worker: int | None = field(default=None, init=False, repr=False)

    def __getstate__(self) -> dict:
        return {
            "crop": self.crop,
            "jitter": self.jitter,
            "seed": self.seed,
            "_generator": None,
            "_worker": None,
        }

    def _rand(self) -> float:
        info = torch.utils.data.get_worker_info()
        worker = info.id if info is not None else -1
        if self.seed is not None and (self._generator is None or self._worker != worker):
            self._generator = torch.Generator().manual_seed(self.seed + worker + 1)
            self._worker = worker
        return float(torch.rand((), generator=self._generator))

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
