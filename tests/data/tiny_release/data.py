#!/usr/bin/env python3
"""Generate the tiny committed release beside this file (``release/``): format 2, 64 x 64 px, four
items over three splits, seeded. Run it to rebuild the fixture; tests check it reproduces byte for byte.

    python tests/data/tiny_release/data.py [OUT]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image

from siteline.release.layout import item_images, layout_record
from siteline.release.manifest import file_entries, write_manifest

SIZE_PX = 64
ITEMS = [("tiny_p0001_v0000", "train", 1), ("tiny_p0001_v0001", "train", 1), ("tiny_p0002_v0000", "val", 2),
         ("tiny_p0003_v0000", "test", 3)]  # fmt: skip


def _mask(rng: np.random.Generator) -> np.ndarray:
    """0 unchanged, a changed rectangle (1), an ignored band (255)."""
    m = np.zeros((SIZE_PX, SIZE_PX), np.uint8)
    y, x = rng.integers(4, SIZE_PX - 24, 2)
    m[y : y + 16, x : x + 20] = 1
    m[:, : rng.integers(3, 10)] = 255
    return m


def generate(out: Path, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    out = Path(out)
    items = []
    for item_id, split, pair in ITEMS:
        a = rng.integers(0, 256, (SIZE_PX, SIZE_PX, 3), dtype=np.uint8)
        b = a.copy()
        mask = _mask(rng)
        b[mask == 1] = 255 - b[mask == 1]
        for folder, arr in item_images(a, b, mask, padded=False).items():
            (out / split / folder).mkdir(parents=True, exist_ok=True)
            Image.fromarray(arr).save(out / split / folder / f"{item_id}.png", format="PNG")
        valid = mask != 255
        items.append({
            "id": item_id, "split": split, "pair": pair, "view": int(item_id[-1]), "strategy": "v1-orig-f0",
            "coverage": 1.0, "change_ratio": float((mask[valid] == 1).mean()), "valid": float(valid.mean()),
            "size_px": [SIZE_PX, SIZE_PX], "padded_px": [SIZE_PX, SIZE_PX],
        })  # fmt: skip
    doc = {
        "format": 2,
        "layout": layout_record(padded=False),
        "name": "tiny",
        "version": "1.0.0",
        "created": "2026-01-01T00:00:00+00:00",
        "code_version": "fixture",
        "files": [],
        "lineage": {"sites": [], "scenes": [], "pairs": [], "parameters": {}, "seeds": {"fixture": seed}},
        "splits": {"train": [1], "val": [2], "test": [3]},
        "items": items,
        "metric": {"name": "siteline-cd-metrics/1"},
    }
    doc["files"] = file_entries(out)
    write_manifest(out, doc)
    return out


if __name__ == "__main__":
    generate(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent / "release")
