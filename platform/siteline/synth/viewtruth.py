"""The change truth of a view, ray-cast from the synthetic site's analytic surfaces, and a mask scored
against it (precision, recall and F1 of changed, boundary F-score, each changed object's recall,
false-change specks).

A pixel is *changed* where the surface its ray meets first in either epoch is absent from the other
epoch (absent: no surface with the same key and signature, siteline.synth.primitives.Primitive),
unless the other epoch's version of that surface (same key) crosses the ray within RESOLUTION_M of
the hit (the rim of a pit that deepened has hardly moved);
*ignore* where either ray meets a surface of an ignored class or outside the fence, or where a ray
meets nothing and the other meets a surface that did not change; else *unchanged*. Nothing here
comes from siteline.render, so what the renderer gets wrong counts against the mask.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from siteline.camera.pinhole import Camera
from siteline.codes import CHANGED, IGNORE, UNCHANGED
from siteline.errors import SynthError
from siteline.site.fence import inside_fence
from siteline.synth.primitives import Primitive
from siteline.synth.raycast import MISS, SurfaceHits, camera_rays, cast, distances

# a surface whose other version (same key, other signature) crosses the ray this close to the hit
# (metres along the ray) is not changed there: the labels' level-of-detection floor
RESOLUTION_M = 0.05
# a false-change component under this many pixels is a speck
SPECK_PX = 30
# the boundary F-score's tolerance (pixels)
BOUNDARY_PX = 2
# an object's false change is quoted when the views show it unchanged on at least this many scored
# pixels (a stockpile seen on 13 pixels of one view, one of them labelled changed, is not 7.7 %)
KEPT_MIN_PX = 100
# a view shows a changed object when the truth has at least this many of its changed pixels there
SHOWN_MIN_PX = 50


@dataclass(frozen=True)
class ViewTruth:
    """mask: (H, W) uint8 0 unchanged, 1 changed, 255 ignore. changed_object: (H, W) int64, the
    object id of the changed surface a changed pixel sees (the first epoch's when both changed), -1
    elsewhere; unchanged_object: the object id an unchanged pixel sees (the first epoch's) when none of
    that object's surfaces changed (an object that stayed), -1 elsewhere. names: object id -> a
    readable name (``<key prefix>#<id>``)."""

    mask: np.ndarray
    changed_object: np.ndarray
    names: dict[int, str]
    unchanged_object: np.ndarray | None = None


def _signatures(prims: Iterable[Primitive]) -> set[tuple[str, str]]:
    return {(p.key, p.signature) for p in prims}


def _object_names(prims: Iterable[Primitive]) -> dict[int, str]:
    return {p.object_id: f"{p.key.split(':')[0]}#{p.object_id}" for p in prims}


def _side(
    hits: SurfaceHits,
    camera: Camera,
    other: Sequence[Primitive],
    ignored: Collection[int],
    fence: Sequence | None,
) -> tuple:
    """Per pixel of one epoch's hits: (hit, changed, not usable, object id)."""
    prims = hits.primitives
    keys = {(p.key, p.signature) for p in other}
    present = np.array([(p.key, p.signature) in keys for p in prims] + [True])  # last slot: a miss
    ign = np.array([p.las_class in ignored for p in prims] + [False])
    obj = np.array([p.object_id for p in prims] + [-1], dtype=np.int64)
    which = np.where(hits.which == MISS, len(prims), hits.which)
    hit = hits.which != MISS
    bad = ign[which]
    if fence is not None and hit.any():
        pts = hits.points[hit]
        out = np.zeros(hit.shape, bool)
        out[hit] = ~inside_fence(pts[:, :2], fence)
        bad |= out
    changed = hit & ~present[which]
    versions = {p.key: p for p in other}
    if changed.any():
        rays = camera_rays(camera)
        flat = changed.ravel()
        for i, prim in enumerate(prims):
            moved = versions.get(prim.key)
            if moved is None or present[i]:
                continue
            px = np.flatnonzero(flat & (hits.which.ravel() == i))
            if len(px):
                t = distances(np.broadcast_to(rays.origin, (len(px), 3)), rays.dirs[px], moved)
                flat[px[np.abs(t - hits.distance.ravel()[px]) <= RESOLUTION_M]] = False
        changed = flat.reshape(changed.shape)
    return hit, changed, bad, obj[which]


def view_truth(
    camera: Camera,
    first: Sequence[Primitive],
    second: Sequence[Primitive],
    ignored_classes: Collection[int] = (),
    fence: Sequence[Sequence[float]] | None = None,
) -> ViewTruth:
    """The truth of ``camera`` (at the render scale) between the epochs whose surfaces are ``first``
    and ``second``. ignored_classes: LAS codes of surfaces the taxonomy ignores; fence: site-local
    ring (metres), None for none."""
    if not first or not second:
        raise SynthError("a view's truth needs the surfaces of both epochs.")
    ha, hb = cast(camera, first), cast(camera, second)
    hit_a, changed_a, bad_a, obj_a = _side(ha, camera, second, ignored_classes, fence)
    hit_b, changed_b, bad_b, obj_b = _side(hb, camera, first, ignored_classes, fence)
    changed = changed_a | changed_b
    ignore = bad_a | bad_b | (~changed & ~(hit_a & hit_b))
    mask = np.where(ignore, IGNORE, np.where(changed, CHANGED, UNCHANGED)).astype(np.uint8)
    obj = np.where(mask == CHANGED, np.where(changed_a, obj_a, obj_b), -1)
    sig_a, sig_b = _signatures(first), _signatures(second)
    moved = [p.object_id for p in first if (p.key, p.signature) not in sig_b]
    moved += [p.object_id for p in second if (p.key, p.signature) not in sig_a]
    kept = np.where((mask == UNCHANGED) & ~np.isin(obj_a, moved), obj_a, -1)
    return ViewTruth(mask, obj, _object_names(first) | _object_names(second), kept)


def _boundary(region: np.ndarray) -> np.ndarray:
    return region & ~ndimage.binary_erosion(region, structure=np.ones((3, 3), bool), border_value=0)


@dataclass
class MaskScore:
    """A mask's agreement with the truth, summed over views, on the pixels both label (neither 255).

    tp, fp, fn, tn: changed-class confusion. boundary: [predicted boundary pixels within
    BOUNDARY_PX of a true one, predicted boundary pixels, true boundary pixels within BOUNDARY_PX of a
    predicted one, true boundary pixels]. objects: object name -> [changed pixels found, changed
    pixels]. specks: per view, the false-changed components under SPECK_PX pixels that lie on
    unchanged ground, more than BOUNDARY_PX from any truly changed pixel, scored or ignored by the mask
    (a speck a model would learn as change); rims: per view, those under SPECK_PX within BOUNDARY_PX of
    a truly changed pixel (an edge drawn a pixel too far, in pieces: counted, and already in precision
    and boundary F).
    kept_objects: object name -> [its truly unchanged pixels labelled changed, its truly unchanged
    pixels the mask labels] (false change per object that stayed). rim_px: the false-changed pixels
    within BOUNDARY_PX of a truly changed one (a change drawn too wide; of ``fp``). scored: pixels
    both label; pixels: every pixel; defined: pixels the truth labels; dropped: those of them the mask
    ignores. shown: changed object name -> the views whose truth shows at least SHOWN_MIN_PX of its
    changed pixels, and [its truly changed pixels the mask ignores, its truly changed pixels, those
    the mask labels unchanged] over all views (``ignored``; the last: what lies behind it labelled
    in its place, see-through, where it stands before an unchanged surface)."""

    tp: int = 0
    fp: int = 0
    fn: int = 0
    tn: int = 0
    boundary: list[int] = field(default_factory=lambda: [0, 0, 0, 0])
    objects: dict[str, list[int]] = field(default_factory=dict)
    specks: list[int] = field(default_factory=list)
    rims: list[int] = field(default_factory=list)
    scored: int = 0
    pixels: int = 0
    kept_objects: dict[str, list[int]] = field(default_factory=dict)
    defined: int = 0
    dropped: int = 0
    rim_px: int = 0
    shown: dict[str, int] = field(default_factory=dict)
    ignored: dict[str, list[int]] = field(default_factory=dict)

    def add(self, predicted: np.ndarray, truth: ViewTruth) -> None:
        """Score one view's mask (H, W) 0/1/255 against its truth."""
        if predicted.shape != truth.mask.shape:
            raise SynthError(f"mask of {predicted.shape} px scored against a truth of {truth.mask.shape} px.")
        both = (predicted != IGNORE) & (truth.mask != IGNORE)
        p, t = both & (predicted == CHANGED), both & (truth.mask == CHANGED)
        self.tp += int((p & t).sum())
        self.fp += int((p & ~t).sum())
        self.fn += int((~p & t).sum())
        self.tn += int((both & ~p & ~t).sum())
        self.scored += int(both.sum())
        self.pixels += int(predicted.size)
        defined = truth.mask != IGNORE
        self.defined += int(defined.sum())
        self.dropped += int((defined & (predicted == IGNORE)).sum())
        if truth.unchanged_object is not None:
            kept = both & (truth.mask == UNCHANGED) & (truth.unchanged_object >= 0)
            ids, inverse = np.unique(truth.unchanged_object[kept], return_inverse=True)
            total = np.bincount(inverse, minlength=len(ids))
            false = np.bincount(inverse, weights=p[kept], minlength=len(ids))
            for oid, n, f in zip(ids, total, false, strict=True):
                got = self.kept_objects.setdefault(truth.names.get(int(oid), f"object#{int(oid)}"), [0, 0])
                got[0] += int(f)
                got[1] += int(n)
        bp, bt = _boundary(p), _boundary(t)
        near_t = ndimage.distance_transform_edt(~bt) <= BOUNDARY_PX if bt.any() else np.zeros_like(bt)
        near_p = ndimage.distance_transform_edt(~bp) <= BOUNDARY_PX if bp.any() else np.zeros_like(bp)
        self.boundary[0] += int((bp & near_t).sum())
        self.boundary[1] += int(bp.sum())
        self.boundary[2] += int((bt & near_p).sum())
        self.boundary[3] += int(bt.sum())
        truly = truth.mask == CHANGED
        for oid in np.unique(truth.changed_object[truly]):
            name = truth.names.get(int(oid), f"object#{int(oid)}")
            mine = truly & (truth.changed_object == oid)
            n = int(mine.sum())
            self.shown[name] = self.shown.get(name, 0) + (n >= SHOWN_MIN_PX)
            dropped = self.ignored.setdefault(name, [0, 0, 0])
            dropped[0] += int((mine & (predicted == IGNORE)).sum())
            dropped[1] += n
            dropped[2] += int((mine & (predicted == UNCHANGED)).sum())
        for oid in np.unique(truth.changed_object[t]):
            name = truth.names.get(int(oid), f"object#{int(oid)}")
            mine = t & (truth.changed_object == oid)
            got = self.objects.setdefault(name, [0, 0])
            got[0] += int((mine & p).sum())
            got[1] += int(mine.sum())
        labels, n = ndimage.label(p & ~t, structure=np.ones((3, 3), bool))
        sizes = np.bincount(labels.ravel(), minlength=n + 1)[1:]
        # near a truly changed pixel, scored or not: a change the mask ignores still has its edge there
        near_change = (
            ndimage.distance_transform_edt(~truly) <= BOUNDARY_PX if truly.any() else np.zeros_like(t)
        )
        self.rim_px += int((p & ~t & near_change).sum())
        touching = np.zeros(n + 1, bool)
        touching[np.unique(labels[near_change & (labels > 0)])] = True
        small = sizes < SPECK_PX
        self.specks.append(int((small & ~touching[1:]).sum()))
        self.rims.append(int((small & touching[1:]).sum()))

    @property
    def precision(self) -> float:
        return self.tp / (self.tp + self.fp) if self.tp + self.fp else float("nan")

    @property
    def recall(self) -> float:
        return self.tp / (self.tp + self.fn) if self.tp + self.fn else float("nan")

    @property
    def f1(self) -> float:
        d = 2 * self.tp + self.fp + self.fn
        return 2 * self.tp / d if d else float("nan")

    @property
    def boundary_f(self) -> float:
        bp, np_, bt, nt = self.boundary
        p = bp / np_ if np_ else 0.0
        r = bt / nt if nt else 0.0
        return 2 * p * r / (p + r) if p + r else 0.0

    def object_recall(self, min_pixels: int = 1) -> dict[str, float]:
        """Recall of each changed object seen on at least ``min_pixels`` scored pixels."""
        return {k: v[0] / v[1] for k, v in sorted(self.objects.items()) if v[1] >= min_pixels}

    def false_change(self, min_pixels: int = 1) -> dict[str, float]:
        """Per object that stayed (seen unchanged on at least ``min_pixels`` scored pixels), the share of
        its truly unchanged pixels the mask labels changed."""
        return {k: v[0] / v[1] for k, v in sorted(self.kept_objects.items()) if v[1] >= min_pixels}

    def object_views(self) -> dict[str, int]:
        """Per changed object, the views that show it (:data:`SHOWN_MIN_PX` truly changed pixels)."""
        return dict(sorted(self.shown.items()))

    def object_ignored(self) -> dict[str, float]:
        """Per changed object, the share of its truly changed pixels the mask ignores."""
        return {k: v[0] / v[1] for k, v in sorted(self.ignored.items()) if v[1]}

    def object_through(self) -> dict[str, float]:
        """Per changed object, the share of its truly changed pixels the mask labels unchanged: where
        it stands before an unchanged surface (a pole, a jib, a fence panel over the ground), the
        surface behind labelled in its place (see-through; an upper bound of it: a 3D label that
        missed the object counts too)."""
        return {k: v[2] / v[1] for k, v in sorted(self.ignored.items()) if v[1]}

    @property
    def dropped_share(self) -> float:
        """The share of the pixels the truth labels that the mask ignores."""
        return self.dropped / self.defined if self.defined else float("nan")

    def to_dict(self) -> dict[str, object]:
        return {
            "false_change": self.false_change(KEPT_MIN_PX),
            "dropped_share": self.dropped_share,
            "precision": self.precision,
            "recall": self.recall,
            "f1": self.f1,
            "boundary_f": self.boundary_f,
            "object_recall": self.object_recall(),
            "object_views": self.object_views(),
            "object_ignored": self.object_ignored(),
            "object_through": self.object_through(),
            "specks_median": float(np.median(self.specks)) if self.specks else float("nan"),
            "specks_max": max(self.specks, default=0),
            "rims_median": float(np.median(self.rims)) if self.rims else float("nan"),
            "views": len(self.specks),
            "scored_share": self.scored / self.pixels if self.pixels else float("nan"),
            "confusion": {"tp": self.tp, "fp": self.fp, "fn": self.fn, "tn": self.tn},
            "rim_px": self.rim_px,
        }
