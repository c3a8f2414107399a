"""Rendering one view of a pair: both scenes through the same camera, and the symmetric 2D change
mask (DESIGN.md §4, §6)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from siteline.cameras import Camera
from siteline.codes import CHANGED as MASK_CHANGED
from siteline.codes import IGNORE as MASK_IGNORE
from siteline.codes import UNCHANGED as MASK_UNCHANGED
from siteline.errors import LabelError
from siteline.labels.change import CHANGED, IGNORED
from siteline.records.enums import HOLE_RULES
from siteline.render.colour import ColourPlan
from siteline.render.zbuffer import render_points
from siteline.stores import join
from siteline.tiles.reader import SceneTiles

if TYPE_CHECKING:
    from siteline.pairs.params import PairParams


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


def pair_mask(
    hit_a: np.ndarray,
    change_a: np.ndarray,
    hit_b: np.ndarray,
    change_b: np.ndarray,
    one_side_hole: str = "ignore",
) -> np.ndarray:
    """Union of the two change renders; 255 where either missed or its winner is ignored.

    ``one_side_hole``: a pixel whose one render hit a *changed* point while the other render has a
    hole (no point) is ``ignore`` (the default: the hole leaves the pixel unverified), or ``changed``
    (the side that sees something saw it change; 24 % of the changed pixels of a 300-view run at 10
    points/m2 are such pixels). Holes next to unchanged points stay ignore either way."""
    if one_side_hole not in HOLE_RULES:
        raise LabelError(f"one_side_hole {one_side_hole!r}: use one of {HOLE_RULES}.")
    ok_a = hit_a & (change_a != IGNORED)
    ok_b = hit_b & (change_b != IGNORED)
    valid = ok_a & ok_b
    changed = (change_a == CHANGED) | (change_b == CHANGED)
    if one_side_hole == "changed":
        seen_change = (ok_a & (change_a == CHANGED) & ~hit_b) | (ok_b & (change_b == CHANGED) & ~hit_a)
        valid = valid | seen_change
    return np.where(valid, np.where(changed, MASK_CHANGED, MASK_UNCHANGED), MASK_IGNORE).astype(np.uint8)


@dataclass(frozen=True)
class LabelledPair:
    """The two scenes of a pair, each read with its change labels (attribute ``change``, from the
    pair's label store, siteline.labels.store)."""

    t1: SceneTiles
    t2: SceneTiles

    @classmethod
    def with_labels(cls, t1: SceneTiles, t2: SceneTiles, label_uri: str) -> LabelledPair:
        """Readers of ``t1`` and ``t2`` that read ``change`` from the pair's label store at ``label_uri``."""
        return cls(
            *(t.with_attribute("change", join(label_uri, side)) for t, side in ((t1, "t1"), (t2, "t2")))
        )


def render_pair_view(
    pair: LabelledPair,
    camera: Camera,
    params: PairParams,
    device: str = "cpu",
    colour: ColourPlan = ColourPlan("rgb"),
) -> PairRender:
    """Render ``camera`` on both scenes with ``params`` (scale, point size, level of detail or
    ``all_points``, ``one_side_hole``: :func:`pair_mask`) in ``colour`` (the pair's RGB, intensity
    or elevation: siteline.render.colour) and build the mask."""
    settings = params.render_settings()
    out = []
    read = 0
    source = colour.attribute
    for side, tiles in ((1, pair.t1), (2, pair.t2)):
        pts = tiles.points_for_view(
            camera,
            params.scale,
            attributes=(source, "change") if source else ("change",),
            lod_factor=params.lod_factor,
            point_size_px=params.point_size_px,
            level=None if params.all_points else "auto",
        )
        read += pts.stats.points_read
        xyz = pts.xyz_m.astype(np.float32)  # site-local: float32 keeps millimetres here
        values = pts.attributes.pop(source) if source else None
        attrs = pts.attributes | {"rgb": colour.colours(side, pts.xyz_m, values)}
        out.append(render_points(xyz, camera, settings, attrs, device=device))
    ra, rb = out
    mask = pair_mask(ra.hit, ra.attributes["change"], rb.hit, rb.attributes["change"], params.one_side_hole)
    n_valid = int((mask != MASK_IGNORE).sum())
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
