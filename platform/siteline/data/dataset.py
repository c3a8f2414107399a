"""A torch Dataset over a siteline release (TorchGeo-style change detection samples)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from PIL import Image
from torch.utils.data import Dataset

from siteline.errors import ReleaseError
from siteline.release.layout import ignore_aware_folder
from siteline.release.manifest import read_manifest

SPLITS = ("train", "val", "test")


class ChangeDetectionDataset(Dataset):
    """Samples ``{"image": float32 (2, 3, H, W) in [0, 1], "mask": int64 (1, H, W) in {0, 1, 255},
    "id": str, "pair": int, "view": int}`` of one split of a release, in id order.

    root: a release folder (``manifest.json``, ``<split>/A|B|label_ignore``; format 1 releases:
    ``<split>/A|B|label``). The mask is always the ignore-aware label (255 = ignore).
    transforms: a callable on the sample dict (e.g. :class:`siteline.data.transforms.TrainTransforms`).
    image_range: 1.0 gives images in [0, 1]; 255.0 gives 0-255 floats (TorchGeo's convention).
    Works with DataLoader workers; importing it needs neither the catalog nor SQLAlchemy.
    """

    def __init__(
        self,
        root: str | Path,
        split: str = "train",
        transforms: Callable[[dict], dict] | None = None,
        image_range: float = 1.0,
    ) -> None:
        self.root = Path(root)
        if image_range not in (1.0, 255.0):
            raise ReleaseError(f"image_range {image_range!r} must be 1.0 (images in [0, 1]) or 255.0.")
        self.image_range = float(image_range)
        if split not in SPLITS:
            raise ReleaseError(f"split {split!r} is not one of {SPLITS}.")
        if not self.root.is_dir():
            raise ReleaseError(
                f"release folder {self.root} does not exist: build and publish one "
                "(`siteline release build`), or pass its path."
            )
        manifest = read_manifest(self.root)
        self.label_folder = ignore_aware_folder(manifest)
        self.items = manifest.items_of(split)
        self.split = split
        self.transforms = transforms
        self.manifest_name = manifest.title
        for it in self.items[:1]:
            for sub in ("A", "B", self.label_folder):
                p = self.root / split / sub / f"{it.id}.png"
                if not p.is_file():
                    raise ReleaseError(
                        f"{p} is missing: the release at {self.root} is incomplete (run `siteline release verify`)."
                    )

    def __len__(self) -> int:
        return len(self.items)

    def _image(self, sub: str, item_id: str) -> torch.Tensor:
        arr = np.asarray(
            Image.open(self.root / self.split / sub / f"{item_id}.png").convert("RGB"), dtype=np.float32
        )
        return torch.from_numpy(arr / (255.0 / self.image_range)).permute(2, 0, 1)

    def __getitem__(self, index: int) -> dict[str, Any]:
        it = self.items[index]
        a, b = self._image("A", it.id), self._image("B", it.id)
        mask = np.asarray(
            Image.open(self.root / self.split / self.label_folder / f"{it.id}.png"), dtype=np.int64
        )
        sample = {
            "image": torch.stack([a, b]),
            "mask": torch.from_numpy(mask)[None],
            "id": it.id,
            "pair": it.pair,
            "view": it.view,
        }
        if self.transforms is not None:
            sample = self.transforms(sample)
        return sample

    def plot(self, index: int) -> Image.Image:
        """t1 | t2 | mask (green unchanged, red changed, white ignore) as one image."""
        from siteline.release.datasheet import colour_mask

        s = self[index]
        k = 255.0 / self.image_range
        a = (s["image"][0].permute(1, 2, 0).numpy() * k).astype(np.uint8)
        b = (s["image"][1].permute(1, 2, 0).numpy() * k).astype(np.uint8)
        m = colour_mask(s["mask"][0].numpy().astype(np.uint8))
        return Image.fromarray(np.concatenate([a, b, m], axis=1))
