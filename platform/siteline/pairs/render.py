"""Rendering one view of a pair: both scenes through the same camera, and the symmetric 2D change
mask (DESIGN.md §4, §6)."""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from siteline.camera.pinhole import Camera
from siteline.codes import CHANGED as MASK_CHANGED
from siteline.codes import IGNORE as MASK_IGNORE
from siteline.codes import IGNORE_CAUSES
from siteline.codes import UNCHANGED as MASK_UNCHANGED
from siteline.errors import LabelError, PairError
from siteline.labels.change import CHANGED, IGNORED, NOT_OBSERVED, UNCHANGED
from siteline.records.enums import HOLE_RULES
from siteline.records.pairs import ColourPlan
from siteline.render.shading import eye_dome
from siteline.render.zbuffer import RenderResult, render_points
from siteline.site.fence import inside_fence
from siteline.stores import join
from siteline.tiles.reader import SceneTiles

if TYPE_CHECKING:
    from siteline.records.params.pairs import PairParams
    from siteline.views.ground import GroundModel


# a hole is a gap between points when a closing of the render's hit mask with a square of this
# half-width fills it (a 7 px closing)
GAP_PX = 3


@dataclass
class PairRender:
    """A view rendered on both scenes. a, b: (H, W, 3) uint8 (black where no point; see ``mask``).
    mask: (H, W) uint8 0 unchanged, 1 changed, 255 ignore (either render missed, or the winning point
    is ignored). coverage_*: fractions of pixels hit (drawn or filled); valid: fraction not ignored;
    change_ratio: changed / valid; ignore: the share of the view's pixels ignored for each of
    :data:`siteline.codes.IGNORE_CAUSES`; filled: the share of pixels whose point came from the gap fill in either
    scene; change_visible: :func:`change_visibility` (None: nothing changed)."""

    a: np.ndarray
    b: np.ndarray
    mask: np.ndarray
    coverage_a: float
    coverage_b: float
    valid: float
    change_ratio: float
    points_read: int
    ignore: dict[str, float] = field(default_factory=dict)
    filled: float = 0.0
    change_visible: float | None = None


# a changed pixel shows its change when A and B differ there by more than this (of 255) in a channel
VISIBLE_DIFFERENCE = 24


def change_visibility(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float | None:
    """The share of ``mask``'s changed pixels where the images ``a`` and ``b`` ((H, W, 3) uint8) differ
    by more than VISIBLE_DIFFERENCE in some channel: how much of the change a person (or a model) can
    see in the pair; None when nothing changed. A slab that gained a floor, seen close, is all changed
    and shows nothing: near 0."""
    changed = mask == MASK_CHANGED
    n = int(changed.sum())
    if not n:
        return None
    diff = np.abs(a[changed].astype(np.int16) - b[changed].astype(np.int16)).max(axis=1)
    return float((diff > VISIBLE_DIFFERENCE).sum() / n)


def pair_mask(
    hit_a: np.ndarray,
    change_a: np.ndarray,
    hit_b: np.ndarray,
    change_b: np.ndarray,
    one_side_hole: str = "ignore",
) -> np.ndarray:
    """Union of the two change renders; 255 where either missed or its winner is ignored, and where
    either winner's place the other scan did not observe (NOT_OBSERVED) unless the other render's
    winner is changed (that side's own evidence).

    ``one_side_hole``: a pixel whose one render hit a *changed* point while the other render has a
    hole (no point) is ``ignore`` (the default: the hole leaves the pixel unverified), or ``changed``
    (the side that sees something saw it change; 24 % of the changed pixels of a 300-view run at 10
    points/m2 are such pixels). Holes next to unchanged points stay ignore either way."""
    if one_side_hole not in HOLE_RULES:
        raise LabelError(f"one_side_hole {one_side_hole!r}: use one of {HOLE_RULES}.")
    seen_a = hit_a & (change_a != IGNORED)
    seen_b = hit_b & (change_b != IGNORED)
    ok_a = seen_a & (change_a != NOT_OBSERVED)
    ok_b = seen_b & (change_b != NOT_OBSERVED)
    changed = (ok_a & (change_a == CHANGED)) | (ok_b & (change_b == CHANGED))
    valid = (ok_a & ok_b) | (changed & seen_a & seen_b)
    if one_side_hole == "changed":
        seen_change = (ok_a & (change_a == CHANGED) & ~hit_b) | (ok_b & (change_b == CHANGED) & ~hit_a)
        valid = valid | seen_change
    return np.where(valid, np.where(changed, MASK_CHANGED, MASK_UNCHANGED), MASK_IGNORE).astype(np.uint8)


def small_gaps(hit: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels without a point that a closing of ``hit`` with a (2 GAP_PX + 1)
    square fills; beyond the image is empty, so a hole open to the image's edge is not a gap."""
    size = 2 * GAP_PX + 1
    dilated = ndimage.maximum_filter(hit, size=size, mode="constant", cval=0)
    closed = ndimage.minimum_filter(dilated, size=size, mode="constant", cval=0)
    return closed & ~hit


def sparse_candidates(change: np.ndarray) -> np.ndarray:
    """(N,) uint8: the rendered points whose surface the renderer looks at for being sparse
    (``render_points``' ``sparse_of``), from their change codes: the labelled ones, changed or not, in
    cells of the larger size (1), the changed ones in both (2: a changed beam's side under its top;
    siteline.render.zbuffer.SPARSE_CELLS, counted for the few changed points alone). A sparse surface
    matters where it stands before a surface of other change: changed before unchanged ground (a pole
    put up), unchanged before a change (a mast before a container taken away); :func:`unsure_edges`
    then ignores what shows between its samples."""
    return np.where(change == CHANGED, 2, np.isin(change, (MASK_UNCHANGED,))).astype(np.uint8)


def unsure_edges(r: RenderResult, change: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels of render ``r`` that show a farther surface where a nearer one may lie
    (``RenderResult.unsure_of``: the edge trim gave them away, or they are holes between the nearer
    surface's samples) and whose change differs from that nearer surface's (``change``: (N,) the
    rendered points' codes). Which of the two such a pixel shows is closer than the points can say:
    a jib three points wide lost a third of its width to the ground behind it, labelled unchanged
    (issue 67), so the mask ignores them; and the pixels of an unchanged surface on the rim of a
    farther changed one (:func:`occluding_rims`)."""
    out = np.zeros(r.hit.shape, bool)
    if r.unsure_of is None:
        return out
    at = r.unsure_of >= 0
    near = change[r.unsure_of[at]] == CHANGED
    shown = r.attributes["change"][at] == CHANGED
    out[at] = near != shown
    return out | occluding_rims(r)


def occluding_rims(r: RenderResult) -> np.ndarray:
    """(H, W) bool: the pixels of render ``r`` that show an unchanged surface next to (one of their 8
    neighbours) a changed one that lies farther. There a nearer surface's disks meet the changed one
    behind it (the ground in front of a fence panel's foot, a car's or a trench's rim), and which of
    the two the pixel shows is a matter of how far the disks reach, not of the points: the ground's
    splats took the bottom rows of a panel taken away (the sloped scene, docs/performance.md)."""
    shown = r.attributes["change"]
    changed_depth = np.where(r.hit & (shown == CHANGED), r.depth, -np.inf).astype(np.float32)
    around = np.ones((3, 3), bool)
    around[1, 1] = False
    farthest = ndimage.maximum_filter(changed_depth, footprint=around, mode="constant", cval=-np.inf)
    return r.hit & (shown == UNCHANGED) & (farthest > r.depth)


def ignore_causes(
    ra: RenderResult, rb: RenderResult, mask: np.ndarray, outside: np.ndarray, unsure: np.ndarray
) -> dict[str, float]:
    """The share of the view's pixels that ``mask`` ignores for each of
    :data:`siteline.codes.IGNORE_CAUSES`, each pixel under the first cause that holds. ra, rb: the two renders (``change`` attribute);
    outside: (H, W) bool, a winning point lies outside the site fence."""
    left = mask == MASK_IGNORE
    gap = small_gaps(ra.hit) | small_gaps(rb.hit)
    empty_a, empty_b = ~ra.hit, ~rb.hit
    unseen = (ra.hit & (ra.attributes["change"] == NOT_OBSERVED)) | (
        rb.hit & (rb.attributes["change"] == NOT_OBSERVED)
    )
    found = {
        "gap": gap,
        "no_surface": empty_a & empty_b,
        "one_side": empty_a | empty_b,
        "outside_fence": outside,
        "not_observed": unseen,
        "unsure_edge": unsure,
        "ignored_class": np.ones_like(left),
    }
    out = {}
    order = ("gap", "no_surface", "one_side", "outside_fence", "not_observed", "unsure_edge", "ignored_class")
    for cause in order:
        mine = left & found[cause]
        out[cause] = float(mine.sum() / mask.size) if mask.size else 0.0
        left &= ~mine
    return {c: out[c] for c in IGNORE_CAUSES}


def _outside(r: RenderResult, xyz_m: np.ndarray, fence: Sequence[Sequence[float]] | None) -> np.ndarray:
    """(H, W) bool: pixels whose winning point of ``r`` is ignored and lies outside ``fence``."""
    out = np.zeros(r.hit.shape, bool)
    if fence is None:
        return out
    rows, cols = np.nonzero(r.hit & (r.attributes["change"] == IGNORED))
    if len(rows):
        away = ~inside_fence(xyz_m[r.index[rows, cols], :2], fence)
        out[rows[away], cols[away]] = True
    return out


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
    fence: Sequence[Sequence[float]] | None = None,
    ground: GroundModel | None = None,
) -> PairRender:
    """Render ``camera`` on both scenes with ``params`` (scale, point size, splats and gap fill,
    level of detail or ``all_points``, ``one_side_hole``: :func:`pair_mask`, ``unsure_edges``:
    :func:`unsure_edges` ignored) in ``colour`` (the
    pair's RGB, intensity or elevation: siteline.render.colour), build the mask and say why each
    ignored pixel is ignored (``fence``: the site's, site-local metres, which made points outside it
    ignore; None when it has none). A height colour needs the pair's ``ground`` (the views' model)."""
    if colour.source == "height" and ground is None:
        raise PairError("a height colour plan needs the pair's ground model to render.")
    settings = params.render_settings()
    source = colour.attribute

    def side(k: int, tiles: SceneTiles) -> tuple[RenderResult, np.ndarray, np.ndarray, int]:
        pts = tiles.points_for_view(
            camera,
            params.scale,
            attributes=(source, "change") if source else ("change",),
            lod_factor=params.lod_factor,
            point_size_px=params.point_size_px,
            level=None if params.all_points else "auto",
        )
        xyz = pts.xyz_m.astype(np.float32)  # site-local: float32 keeps millimetres here
        values = pts.attributes.pop(source) if source else None
        if colour.source == "height":
            values = ground.height(pts.xyz_m)  # type: ignore[union-attr]
        attrs = pts.attributes | {"rgb": colour.colours(k, pts.xyz_m, values)}
        sparse_of = sparse_candidates(pts.attributes["change"])
        r = render_points(xyz, camera, settings, attrs, device, pts.spacing_m, sparse_of)
        if colour.shading == "edl":  # intensity or elevation alone show no edges: shade by depth
            r.attributes["rgb"] = eye_dome(r.rgb, r.depth)
        unsure = unsure_edges(r, pts.attributes["change"])
        return r, _outside(r, pts.xyz_m, fence), unsure, pts.stats.points_read

    # the two scenes' reads and renders run at once: most of a render is compiled loops and zarr's
    # decoding, which release the GIL (each side has its own reader and chunk cache)
    with ThreadPoolExecutor(2) as pool:
        (ra, out_a, unsure_a, read_a), (rb, out_b, unsure_b, read_b) = pool.map(
            side, (1, 2), (pair.t1, pair.t2)
        )
    outside, unsure, read = (out_a, out_b), (unsure_a, unsure_b), read_a + read_b
    mask = pair_mask(ra.hit, ra.attributes["change"], rb.hit, rb.attributes["change"], params.one_side_hole)
    edge = (unsure[0] | unsure[1]) & (mask != MASK_IGNORE) & params.unsure_edges
    mask[edge] = MASK_IGNORE
    n_valid = int((mask != MASK_IGNORE).sum())
    filled = (ra.filled | rb.filled) if ra.filled is not None and rb.filled is not None else None
    return PairRender(
        ra.rgb,
        rb.rgb,
        mask,
        ra.coverage,
        rb.coverage,
        n_valid / mask.size,
        float((mask == MASK_CHANGED).sum() / n_valid) if n_valid else 0.0,
        read,
        ignore_causes(ra, rb, mask, outside[0] | outside[1], edge),
        float(filled.mean()) if filled is not None and filled.size else 0.0,
        change_visibility(ra.rgb, rb.rgb, mask),
    )
