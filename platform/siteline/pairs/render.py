"""Rendering one view of a pair: both scenes through the same camera, and the symmetric 2D change
mask (DESIGN.md §4, §6)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from siteline.cameras import Camera
from siteline.codes import CHANGED as MASK_CHANGED
from siteline.codes import IGNORE as MASK_IGNORE
from siteline.codes import UNCHANGED as MASK_UNCHANGED
from siteline.labels.change import CHANGED, IGNORED
from siteline.render import RenderSettings, render_points
from siteline.tiles.reader import SceneTiles


@dataclass
class PairRender:
    """A view rendered on both scenes. a, b: (H, W, 3) uint8 (black where no point; see ``mask``).
    mask: (H, W) uint8 0 unchanged, 1 changed, 255 ignore (either render missed, or the winning point
    is ignored). coverage_*: fractions of pixels hit; valid: fraction not ignored; change_ratio:
    changed / valid."""

    a: np.ndarray
    b: np.ndarray
    mask: np.ndarray
    coverage_a: float
    coverage_b: float
    valid: float
    change_ratio: float
    points_read: int


def pair_mask(hit_a: np.ndarray, change_a: np.ndarray, hit_b: np.ndarray, change_b: np.ndarray) -> np.ndarray:
    """Union of the two change renders; 255 where either missed or its winner is ignored."""
    valid = hit_a & hit_b & (change_a != IGNORED) & (change_b != IGNORED)
    changed = (change_a == CHANGED) | (change_b == CHANGED)
    return np.where(valid, np.where(changed, MASK_CHANGED, MASK_UNCHANGED), MASK_IGNORE).astype(np.uint8)


def render_pair_view(
    t1: SceneTiles,
    t2: SceneTiles,
    camera: Camera,
    scale: float,
    point_size_px: int,
    lod_factor: float = 1.0,
    device: str = "cpu",
) -> PairRender:
    """Render ``camera`` at ``scale`` on both scenes (their tile stores must carry the pair's
    ``change`` labels) and build the mask."""
    settings = RenderSettings(scale=scale, point_size_px=point_size_px)
    out = []
    read = 0
    for tiles in (t1, t2):
        pts = tiles.points_for_view(camera, scale, attributes=("rgb", "change"), lod_factor=lod_factor)
        read += tiles.last_stats.points_read
        out.append(
            render_points(
                pts["xyz"], camera, settings, {"rgb": pts["rgb"], "change": pts["change"]}, device=device
            )
        )
    ra, rb = out
    mask = pair_mask(ra.hit, ra.attributes["change"], rb.hit, rb.attributes["change"])
    valid = mask != MASK_IGNORE
    n_valid = int(valid.sum())
    return PairRender(
        ra.rgb,
        rb.rgb,
        mask,
        ra.coverage,
        rb.coverage,
        n_valid / mask.size,
        float((mask == MASK_CHANGED).sum() / n_valid) if n_valid else 0.0,
        read,
    )
