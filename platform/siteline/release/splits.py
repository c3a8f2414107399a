"""Splits of a release: stable across versions, never empty while there are views to split.

- An item (pair, view index) that an earlier version of the release holds keeps its split in every
  later version, and a view an earlier version left out (a train view on val or test ground) stays
  left out; a new view of such a pair takes the split (or the leaving out) of the pair's nearest (by
  ground anchor) view that kept one; a new pair goes whole to the split furthest under its share.
- A first version of three or more pairs assigns whole pairs (seeded): no view of a pair in two splits.
- With fewer pairs than splits, each pair's views are cut into spatial bands along an axis of their
  ground anchors (test the first ``test_fraction`` of them, val the last ``val_fraction``): the long
  axis, unless another direction puts more of the pair's change in both val and test (a split
  without changed pixels cannot score change); a train view is left out of the release while a val
  or test view shares more than ``MAX_SHARED`` of its footprint with train views, at most half of
  the train views (footprints as discs: anchor = where the view's optical axis meets the ground,
  radius = that distance x half the image diagonal / focal length).
- Every version states the largest share of a val or test view's footprint that train views of the
  same pair also show, and the items left out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely

from siteline.records.pairs import RenderedView
from siteline.records.release import SplitRule

SPLITS = ("train", "val", "test")
# an item an earlier version left out of every split (it stays out)
LEFT_OUT = "left_out"
# the most of a val or test view's footprint that train views may cover (single-pair band splits)
MAX_SHARED = 0.5
# band directions tried (degrees from the long axis), in order of preference
_BAND_ANGLES_DEG = (0.0, 90.0, 45.0, 135.0, 22.5, 67.5, 112.5, 157.5)
Item = tuple[int, int]  # (pair id, view index)


@dataclass(frozen=True)
class SplitPlan:
    """Each item's split, the items left out (train views too close to val/test ground), and the rule
    as the manifest states it."""

    of: dict[Item, str]
    left_out: tuple[Item, ...] = ()
    rule: SplitRule = field(default_factory=SplitRule)

    def stated(self, views: Mapping[int, Sequence[RenderedView]]) -> SplitPlan:
        """This plan with its rule stating the largest share of a val or test view's footprint that
        train views of the same pair show, the items left out, and each split's changed share."""
        worst = max_shared_footprint(views, self.of)
        changed = {}
        for split in SPLITS:
            mine = [v for p, vs in views.items() for v in vs if self.of.get((p, v.index)) == split]
            valid = sum(v.valid for v in mine)
            changed[split] = round(sum(v.valid * v.change_ratio for v in mine) / valid, 4) if valid else None
        rule = self.rule | {
            "target_shared_footprint": MAX_SHARED, "max_shared_footprint": round(worst, 3),
            "left_out": len(self.left_out), "left_out_items": [list(i) for i in sorted(self.left_out)],
            "changed_share": changed,
        }  # fmt: skip
        return SplitPlan(self.of, self.left_out, rule)

    def pairs(self) -> dict[str, list[int]]:
        """The pairs with items in each split."""
        return {s: sorted({p for (p, _), sp in self.of.items() if sp == s}) for s in ("test", "val", "train")}


def split_pairs(
    pair_ids: list[int], seed: int, val_fraction: float = 0.15, test_fraction: float = 0.15
) -> dict[str, list[int]]:
    """Assign whole pairs to train/val/test (seeded): no view of one pair lands in two splits.
    One pair: all train. Two: train and test. Three or more: at least one each for val and test."""
    ids = sorted(pair_ids)
    order = [ids[i] for i in np.random.default_rng(seed).permutation(len(ids))]
    n = len(order)
    n_test = 0 if n < 2 else max(1, round(test_fraction * n))
    n_val = 0 if n < 3 else max(1, round(val_fraction * n))
    return {
        "test": sorted(order[:n_test]),
        "val": sorted(order[n_test : n_test + n_val]),
        "train": sorted(order[n_test + n_val :]),
    }


def footprint_disc(view: RenderedView) -> tuple[np.ndarray, float]:
    """(anchor xy, radius m) of a view's ground footprint as a disc (module docstring)."""
    cam = view.camera
    depth = float(view.params.central_depth_m or 0.0) or max(float(cam.center[2]), 1.0)
    anchor = cam.center + cam.forward * depth
    radius = depth * math.hypot(cam.width, cam.height) / (2.0 * cam.fx)
    return anchor[:2], radius


def max_shared_footprint(views: Mapping[int, Sequence[RenderedView]], of: Mapping[Item, str]) -> float:
    """The largest share of a val or test view's footprint that train views of the same pair cover."""
    worst = 0.0
    for p, vs in views.items():
        shapes = {v.index: _disc(v) for v in vs if (p, v.index) in of}
        train = [shapes[v.index] for v in vs if of.get((p, v.index)) == "train"]
        if not train:
            continue
        covered = shapely.union_all(train)
        for v in vs:
            if of.get((p, v.index)) in ("val", "test"):
                worst = max(worst, float(covered.intersection(shapes[v.index]).area / shapes[v.index].area))
    return worst


def _disc(view: RenderedView) -> shapely.Polygon:
    (x, y), r = footprint_disc(view)
    return shapely.Point(float(x), float(y)).buffer(r, 32)


def assign_splits(
    views: Mapping[int, Sequence[RenderedView]],
    seed: int,
    previous: Mapping[Item, str] | None = None,
    val_fraction: float = 0.15,
    test_fraction: float = 0.15,
) -> SplitPlan:
    """The split of every item of ``views`` (pair id -> its rendered views), keeping ``previous``
    (the latest earlier version's items: a split, or :data:`LEFT_OUT`) where it can (module
    docstring), with the rule stating the shared footprint and what was left out."""
    return _assign(views, seed, dict(previous or {}), val_fraction, test_fraction).stated(views)


def _assign(
    views: Mapping[int, Sequence[RenderedView]],
    seed: int,
    previous: dict[Item, str],
    val_fraction: float,
    test_fraction: float,
) -> SplitPlan:
    known = {p for p, _ in previous}
    pairs = sorted(views)
    shares = {"train": 1.0 - val_fraction - test_fraction, "val": val_fraction, "test": test_fraction}
    if not known:
        if len(pairs) >= len(SPLITS):
            whole = split_pairs(pairs, seed, val_fraction, test_fraction)
            first = {(p, v.index): s for s, ids in whole.items() for p in ids for v in views[p]}
            return SplitPlan(first, (), {"rule": "whole pairs, seeded", "seed": seed})
        return _bands(views, val_fraction, test_fraction)
    of: dict[Item, str] = {}
    left: list[Item] = []
    for p in pairs:
        if p not in known:
            continue
        kept = {v.index: previous[(p, v.index)] for v in views[p] if (p, v.index) in previous}
        discs = {v.index: footprint_disc(v)[0] for v in views[p]}
        for v in views[p]:
            if v.index in kept:
                split = kept[v.index]
            elif kept:
                near = min(kept, key=lambda i: float(np.linalg.norm(discs[i] - discs[v.index])))
                split = kept[near]
            else:
                split = "train"
            if split == LEFT_OUT:
                left.append((p, v.index))
            else:
                of[(p, v.index)] = split
    for p in pairs:  # new pairs, whole, to the split furthest under its share of pairs
        if p in known:
            continue
        counts = {s: len({q for (q, _), sp in of.items() if sp == s}) for s in SPLITS}
        total = max(sum(counts.values()), 1)
        want = min(SPLITS, key=lambda s: (counts[s] / total - shares[s], SPLITS.index(s)))
        of |= {(p, v.index): want for v in views[p]}
    return SplitPlan(of, tuple(left), {"rule": "items keep their split (and views left out stay out); new views "
                                              "take their nearest view's, new pairs the split furthest under its "
                                              "share", "seed": seed})  # fmt: skip


def _shared(shapes: Sequence[shapely.Polygon], train: set[int], k: int) -> float:
    """The share of footprint ``k`` that the footprints of ``train`` cover."""
    if not train:
        return 0.0
    return float(shapely.union_all([shapes[t] for t in train]).intersection(shapes[k]).area / shapes[k].area)


def _changed(vs: Sequence[RenderedView], band: np.ndarray) -> float:
    """The changed share of the valid pixels of views ``band`` (positions into ``vs``)."""
    valid = sum(vs[k].valid for k in band)
    return sum(vs[k].valid * vs[k].change_ratio for k in band) / valid if valid else 0.0


def _band_order(
    xy: np.ndarray, vs: Sequence[RenderedView], n_test: int, n_val: int
) -> tuple[np.ndarray, float]:
    """The order of views ``vs`` (anchors ``xy``) along the band axis, and that axis's angle from the
    long axis (degrees): the long axis when test and val bands there each hold at least half the
    pair's changed share, else the direction whose poorer band holds the most."""
    centred = xy - xy.mean(axis=0)
    long_axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    overall = _changed(vs, np.arange(len(vs)))
    best: tuple[float, np.ndarray, float] | None = None
    for angle in _BAND_ANGLES_DEG:
        a = np.radians(angle)
        axis = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) @ long_axis
        for sign in (1.0, -1.0):
            order = np.argsort(sign * (centred @ axis), kind="stable")
            poorer = min(_changed(vs, order[:n_test]), _changed(vs, order[len(vs) - n_val :]))
            if angle == 0.0 and sign > 0 and poorer >= 0.5 * overall:
                return order, 0.0
            if best is None or poorer > best[0] + 1e-12:
                best = (poorer, order, angle)
    if best is None or best[0] <= 0.0:
        return np.argsort(centred @ long_axis, kind="stable"), 0.0
    return best[1], best[2]


def _bands(
    views: Mapping[int, Sequence[RenderedView]], val_fraction: float, test_fraction: float
) -> SplitPlan:
    of: dict[Item, str] = {}
    left: list[Item] = []
    directions: dict[int, float] = {}
    for p in sorted(views):
        vs = list(views[p])
        discs = [footprint_disc(v) for v in vs]
        xy = np.array([d[0] for d in discs]) if discs else np.zeros((0, 2))
        if len(vs) < 3:
            of |= {(p, v.index): "train" for v in vs}
            continue
        n_test = max(1, round(test_fraction * len(vs)))
        n_val = max(1, round(val_fraction * len(vs)))
        order, angle = _band_order(xy, vs, n_test, n_val)
        directions[p] = angle
        split = np.full(len(vs), "train", dtype=object)
        split[order[:n_test]] = "test"
        split[order[len(vs) - n_val :]] = "val"
        shapes = [shapely.Point(float(x), float(y)).buffer(r, 32) for (x, y), r in discs]
        train = {k for k in range(len(vs)) if split[k] == "train"}
        budget = len(train) // 2  # never more than half of train left out: a small site keeps a train set
        held = [k for k in range(len(vs)) if split[k] != "train"]

        for k in held:
            while train and budget and _shared(shapes, train, k) > MAX_SHARED:
                worst = max(train, key=lambda t: shapes[t].intersection(shapes[k]).area)
                train.discard(worst)
                left.append((p, vs[worst].index))
                budget -= 1
        of |= {(p, vs[k].index): str(split[k]) for k in range(len(vs)) if split[k] != "train" or k in train}
    rule: SplitRule = {
        "rule": "fewer pairs than splits: each pair's views in spatial bands along an axis of their ground "
        f"anchors (test the first {test_fraction:.0%}, val the last {val_fraction:.0%}; the long axis unless "
        "another direction gives both more of the pair's change); train views left out while a val or test "
        f"view shares more than {MAX_SHARED:.0%} of its footprint with train, at most half of them (a site "
        "smaller than a few footprints cannot separate further)",
        "band_direction_deg": {str(p): a for p, a in sorted(directions.items())},
    }  # fmt: skip
    return SplitPlan(of, tuple(left), rule)
