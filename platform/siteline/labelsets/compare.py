"""Counting how two label-set versions differ: pure counts over class arrays, and a tile-by-tile
read of a scene under two versions."""

from __future__ import annotations

import numpy as np

from siteline.schema import JSON
from siteline.site.taxonomy import Taxonomy
from siteline.tiles.reader import SceneTiles


def pair_counts(old: np.ndarray, new: np.ndarray) -> np.ndarray:
    """(256, 256) int64 counts of points per (old class id, new class id)."""
    return np.bincount(old.astype(np.int64) * 256 + new, minlength=256 * 256).reshape(256, 256)


def changes_by_class(counts: np.ndarray, taxonomy: Taxonomy) -> dict[str, int]:
    """``"old->new": points`` of every off-diagonal cell of :func:`pair_counts` (class names, ids
    for codes the taxonomy lacks)."""
    names = {c.id: c.name for c in taxonomy.classes}
    out = {}
    for a, b in zip(*np.nonzero(counts), strict=True):
        if a != b:
            out[f"{names.get(int(a), int(a))}->{names.get(int(b), int(b))}"] = int(counts[a, b])
    return dict(sorted(out.items(), key=lambda kv: (-kv[1], kv[0])))


def histogram(counts: np.ndarray, taxonomy: Taxonomy) -> dict[str, int]:
    """Points per class name of the new side of :func:`pair_counts`."""
    per_id = counts.sum(axis=0)
    names = {c.id: c.name for c in taxonomy.classes}
    return {names.get(int(i), str(int(i))): int(per_id[i]) for i in np.nonzero(per_id)[0]}


def diff_tiles(a: SceneTiles, b: SceneTiles, taxonomy: Taxonomy) -> dict[str, JSON]:
    """How the classes of one scene's tiles under two label sets differ, read tile by tile: points,
    changed points, changed points per ``"old->new"`` class pair and both class histograms."""
    counts = np.zeros((256, 256), dtype=np.int64)
    for tile in sorted(a.by_tile):
        old, new = (t.read_tile(tile, ("class",)).attributes["class"] for t in (a, b))
        counts += pair_counts(old, new)
    return {
        "points": int(counts.sum()),
        "changed": int(counts.sum() - np.trace(counts)),
        "changes": changes_by_class(counts, taxonomy),
        "histograms": [histogram(counts.T, taxonomy), histogram(counts, taxonomy)],
    }
