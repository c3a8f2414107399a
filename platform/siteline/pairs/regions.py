"""A pair's changed regions, read from its change labels, for planning its views around them
(siteline.views.changes, siteline.views.generate.cover_changes) and for saying which views show
each (the pair's summary, the release's datasheet)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from siteline.labels.change import CHANGED
from siteline.labels.regions import region_ids
from siteline.pairs.render import LabelledPair
from siteline.records.pairs import ChangedRegion
from siteline.site.fence import inside_fence
from siteline.views.changes import ChangeSample

# changed points are read at this spacing (metres; all of them where the scan is sparser): each
# scene is read at it, so the read grows with the site's surface, not its density
CHANGE_READ_M = 0.2
# they are linked into regions through touching cells of this size (metres: points of one surface
# up to ~1 m apart, a pole flown at 80 points/m2 or a wall at 3), or of the pair's change radius
# where that is larger (a 1.9 points/m2 survey's roof, points 0.7 m apart, fell into 39 pieces in
# 0.5 m cells), and a region's surface is the cells it fills (so its m2 do not depend on the density)
CHANGE_CELL_M = 0.5
# the most a region's surface is taken to exceed the cells its points fill (a sparse scan's)
MAX_UNFILLED = 3.0
# a region is judged from at most this many of its points (every k-th, each standing for k)
SAMPLE_PER_REGION = 256


@dataclass(frozen=True)
class PairChanges:
    """The changed regions of a pair of at least the size asked: their sample for view planning,
    their records (numbered 1.. in the sample's order, views not yet known) and how many smaller
    regions were left out."""

    sample: ChangeSample
    regions: tuple[ChangedRegion, ...]
    smaller: int


def changes_of(
    parts: Sequence[tuple[str, np.ndarray]],
    fence: Sequence[Sequence[float]] | None,
    min_m2: float,
    cell_m: float = CHANGE_CELL_M,
) -> PairChanges:
    """The regions of the changed points ``parts`` ((side, (N, 3) site-local metres) of each scene),
    linked together across the scenes (a stockpile that grew is one region) through touching cells
    of ``cell_m`` metres, which also measure a region's surface; those under ``min_m2`` square metres
    left out; a region is inside ``fence`` when its centre is."""
    xyz = np.concatenate([p for _, p in parts]) if parts else np.zeros((0, 3))
    side = (
        np.concatenate([np.full(len(p), i) for i, (_, p) in enumerate(parts)]) if parts else np.zeros(0, int)
    )
    if not len(xyz):
        return PairChanges(ChangeSample(xyz, np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool)), (), 0)
    ids = region_ids(xyz, cell_m)
    ijk = np.floor(xyz / cell_m).astype(np.int64)
    _, cell, in_cell = np.unique(np.column_stack([ids, ijk]), axis=0, return_inverse=True, return_counts=True)
    cell = cell.ravel()
    weight = cell_m**2 / in_cell[cell]  # a cell's surface shared among its points
    weight *= _unfilled(ids, in_cell[cell])  # ... and the cells a sparse scan left empty
    area = np.bincount(ids, weights=weight)
    big = np.flatnonzero(area >= min_m2)
    big = big[np.argsort(-area[big], kind="stable")]  # the largest first
    xs, rs, ws, records = [], [], [], []
    for new, r in enumerate(big):
        mine = np.flatnonzero(ids == r)
        step = max(1, -(-len(mine) // SAMPLE_PER_REGION))
        at = mine[::step]
        xs.append(xyz[at])
        rs.append(np.full(len(at), new, np.int64))
        ws.append(weight[at] * (area[r] / weight[at].sum()))
        lo, hi = xyz[mine].min(axis=0), xyz[mine].max(axis=0)
        center = (lo + hi) / 2
        sides = tuple(name for i, (name, _) in enumerate(parts) if (side[mine] == i).any())
        cx, cy, cz = (float(v) for v in center)
        sx, sy, sz = (float(v) for v in hi - lo)
        records.append(ChangedRegion(new + 1, sides, float(area[r]), (cx, cy, cz), (sx, sy, sz)))
    centers = np.array([r.center_m[:2] for r in records]).reshape(-1, 2)
    inside = (
        inside_fence(centers, fence) if fence is not None and len(centers) else np.ones(len(records), bool)
    )
    sample = ChangeSample(
        np.concatenate(xs) if xs else np.zeros((0, 3)),
        np.concatenate(rs) if rs else np.zeros(0, np.int64),
        np.concatenate(ws) if ws else np.zeros(0),
        np.asarray(inside, bool),
    )
    return PairChanges(sample, tuple(records), int(len(area) - len(big)))


def _unfilled(ids: np.ndarray, in_cell: np.ndarray) -> np.ndarray:
    """(N,) per point, how many cells its region's surface spans for each cell its points fill:
    points falling at random, lam a cell, leave a share exp(-lam) of the cells empty, and the filled
    ones hold lam / (1 - exp(-lam)) on average (what is measured: ``in_cell``, each point's cell's
    count), so the surface is the filled cells / (1 - exp(-lam)); at most :data:`MAX_UNFILLED`
    (a region of lone points says nothing of its density)."""
    regions = np.bincount(ids)
    filled = np.bincount(ids, weights=1.0 / in_cell)  # each cell counted once through its points
    mean = regions / np.maximum(filled, 1e-12)  # points a filled cell holds
    lam = np.maximum(mean - 1.0, 1e-6) * 2.0  # a start above the root
    for _ in range(30):  # Newton on lam / (1 - exp(-lam)) = mean
        e = np.exp(-lam)
        f = lam / (1 - e) - mean
        df = (1 - e - lam * e) / (1 - e) ** 2
        lam = np.maximum(lam - f / df, 1e-6)
    return np.minimum(1.0 / (1.0 - np.exp(-lam)), MAX_UNFILLED)[ids]


def pair_changes(
    scenes: LabelledPair, fence: Sequence[Sequence[float]] | None, min_m2: float, radius_m: float
) -> PairChanges:
    """:func:`changes_of` the changed points of both scenes of a labelled pair, read at
    :data:`CHANGE_READ_M` (each scene read at that spacing: the cost grows with the site's surface,
    not its density), in cells of :data:`CHANGE_CELL_M` or the change radius ``radius_m``, the
    larger."""
    parts = []
    for side, tiles in (("t1", scenes.t1), ("t2", scenes.t2)):
        read = tiles.points(resolution=CHANGE_READ_M, attributes=("change",))
        parts.append((side, read.xyz_m[read.attributes["change"] == CHANGED]))
    return changes_of(parts, fence, min_m2, max(CHANGE_CELL_M, radius_m))
