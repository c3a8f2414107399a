"""Release format 2 (DESIGN.md §8): what each folder holds, the label encodings and the padding.

Format 1 wrote 0/1/255 to ``<split>/label/``, which every change-detection toolbox misreads. Format 2
keeps ``label/`` for the LEVIR-CD reading every toolbox shares and puts the ignore information beside
it. Pure functions over arrays; the release builder does the I/O.
"""

from __future__ import annotations

import numpy as np

from siteline.codes import CHANGED, IGNORE
from siteline.errors import ReleaseError
from siteline.records.release import FORMAT, Layout, Manifest

FORMAT_1 = "siteline-release/1"

FOLDERS = {
    "A": "t1 image (RGB, 8-bit)",
    "B": "t2 image (RGB, 8-bit), pixel-aligned with A",
    "label": "LEVIR-CD label (8-bit grey): 0 unchanged, 255 changed; ignore pixels are written as 0 "
    "(unchanged), so scores computed on label/ alone count them",
    "ignore": "ignore mask (8-bit grey): 255 where the pixel is ignored (no point rendered in one of the "
    "scenes, or an ignored class: snow, noise, outside the fence), 0 elsewhere",
    "label_ignore": "ignore-aware label (8-bit grey): 0 unchanged, 1 changed, 255 ignore; read it with "
    "ignore_index=255 (siteline.data, siteline.release.metrics, `siteline release score`)",
}
PAD_MULTIPLE_PX = 32
PAD_MIN_SIDE_PX = 256
# what the padding fills each folder with (right and bottom edges)
PAD_FILL = {"A": 0, "B": 0, "label": 0, "ignore": 255, "label_ignore": IGNORE}


def manifest_format(manifest: Manifest) -> int:
    """1 or 2: the format of a release manifest."""
    if manifest.format == FORMAT_1:
        return 1
    if manifest.format == FORMAT:
        return 2
    raise ReleaseError(f"release {manifest.title}: unknown format {manifest.format!r}.")


def ignore_aware_folder(manifest: Manifest) -> str:
    """The folder holding 0/1/255 labels: ``label_ignore`` (format 2) or ``label`` (format 1)."""
    return "label_ignore" if manifest_format(manifest) == 2 else "label"


def levir_label(mask: np.ndarray) -> np.ndarray:
    """LEVIR-CD label of a 0/1/255 mask: (H, W) uint8, 255 changed, 0 unchanged or ignored."""
    return np.where(np.asarray(mask) == CHANGED, 255, 0).astype(np.uint8)


def ignore_mask(mask: np.ndarray) -> np.ndarray:
    """Ignore mask of a 0/1/255 mask: (H, W) uint8, 255 ignored, 0 valid."""
    return np.where(np.asarray(mask) == IGNORE, 255, 0).astype(np.uint8)


def padded_size(
    width_px: int, height_px: int, multiple_px: int = PAD_MULTIPLE_PX, min_side_px: int = PAD_MIN_SIDE_PX
) -> tuple[int, int]:
    """The smallest (width, height) >= the given one, both multiples of ``multiple_px`` and at least
    ``min_side_px`` (706 x 510 -> 736 x 512; 330 x 248 -> 352 x 256)."""

    def side(n: int) -> int:
        n = max(n, min_side_px)
        return -(-n // multiple_px) * multiple_px

    return side(width_px), side(height_px)


def pad(arr: np.ndarray, width_px: int, height_px: int, fill: int) -> np.ndarray:
    """``arr`` (H, W) or (H, W, C) padded on the right and bottom to (height_px, width_px) with ``fill``."""
    h, w = arr.shape[:2]
    if (w, h) == (width_px, height_px):
        return arr
    out = np.full((height_px, width_px) + arr.shape[2:], fill, dtype=arr.dtype)
    out[:h, :w] = arr
    return out


def item_images(a: np.ndarray, b: np.ndarray, mask: np.ndarray, padded: bool) -> dict[str, np.ndarray]:
    """The five arrays of one release item by folder, padded when ``padded``. a, b: (H, W, 3) uint8;
    mask: (H, W) uint8 0/1/255."""
    out = {
        "A": a,
        "B": b,
        "label": levir_label(mask),
        "ignore": ignore_mask(mask),
        "label_ignore": np.asarray(mask, dtype=np.uint8),
    }
    if padded:
        w, h = padded_size(mask.shape[1], mask.shape[0])
        out = {k: pad(v, w, h, PAD_FILL[k]) for k, v in out.items()}
    return out


def layout_record(padded: bool) -> Layout:
    """What the manifest says about the layout: the folders and the padding rule."""
    return {
        "folders": FOLDERS,
        "padding": {
            "enabled": padded,
            "multiple_px": PAD_MULTIPLE_PX,
            "min_side_px": PAD_MIN_SIDE_PX,
            "edges": "right and bottom",
            "fill": PAD_FILL,
            "per_item": "items[].size_px is the rendered size, items[].padded_px the stored size",
        },
    }
