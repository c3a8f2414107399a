"""3D change between two scenes (DESIGN.md §4): pure functions over site-local arrays.

Two rules, one call (:func:`change_flags`):

- *nearest* (DESIGN.md §4 as first written): a point is changed when the other scene has no kept
  point within the radius r. On an unchanged surface sampled at random, 2^(-k^2) of the points (k =
  r / median spacing; 1.3 % at the default 2.5) find no neighbour by chance and are flagged.
- *surface* (the default, :class:`SurfaceTest`): a point the nearest rule flags is looked at again
  against the other scene's local surface: its ``neighbours`` nearest kept points within the search
  radius (SEARCH_MULTIPLIER x r, siteline.records.params.labels). Fewer than 3 there: see below. Else a plane is
  fitted to them (least squares), and the point is unchanged when its distance along the plane's
  normal is within the level of detection, ``lod_sigmas`` x the neighbours' RMS residual to their
  plane (their roughness) and never under ``lod_floor_m`` (range noise and registration error), as
  M3C2 judges a distance against roughness; its class is then compared with its nearest neighbour's
  as before, except that any of the other scene's points within r with the point's class will do
  (its nearest may be a worker standing beside it). A point with nothing of the other scene around it is changed when the other scene
  saw through where it is: its lowest point in the point's cell of a plan grid of the search radius
  lies below it (the ground under a jib that turned away). When all of them lie above it, that
  scene could not see the place from above (the ground in a jib's scan shadow) and the point is
  unchanged: the change, if any, is the other scene's to show. When the other scene has no point
  at all in that cell, it never covered the place (beyond its scan, its fence or a hole in it) and
  the point is ignored: nothing says whether it changed. What it cannot see: a surface that
  moved along itself or by less than the level of detection; a change within r of an unchanged
  surface of the same class; and it takes for change a wall or mast face one scan saw and the
  other's scan shadow hid (the other scene's ground below it shows through in plan).
  With a probe (``SurfaceTest.probe_m``, ``surface_probe`` x r; the releases' default 0.7) a point
  the nearest rule finds a neighbour for, but not a near one (farther than the probe), is probed
  against the other scene's surface the same way, and is changed when it lies off it by more than
  the level of detection and ``offset_m`` (r / 4): ground deepened or raised by less than r (a
  pit's ramps near its rim) is found where the nearest rule alone sees a neighbour within r. On an
  unchanged surface few points are probed (their neighbours lie near) and fewer are off it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

if TYPE_CHECKING:
    from pykdtree.kdtree import KDTree

from siteline.codes import CHANGED, UNCHANGED
from siteline.codes import IGNORE as IGNORED
from siteline.errors import LabelError
from siteline.records.params.labels import SurfaceTest

NN_BACKENDS = ("pykdtree", "ckdtree")


def float32_tree(xyz: np.ndarray) -> KDTree:
    """A pykdtree k-d tree of (N, 3) site-local points in float32 (built once, queried by
    :func:`nearest` and :func:`plane_distances` alike)."""
    from pykdtree.kdtree import KDTree

    return KDTree(np.ascontiguousarray(xyz, dtype=np.float32))


def nearest(
    b_xyz: np.ndarray,
    a_xyz: np.ndarray,
    radius_m: float,
    backend: str = "pykdtree",
    tree: KDTree | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Distance to and index of each query's nearest point of ``b_xyz`` within ``radius_m`` (inf and
    an out-of-range index beyond it). pykdtree works in float32 site-local coordinates (the faster
    here, bench/release.py; ``tree``: its tree of ``b_xyz`` when already built); ckdtree in float64 on
    every core."""
    if backend == "pykdtree":
        tree = tree if tree is not None else float32_tree(b_xyz)
        d, i = tree.query(np.ascontiguousarray(a_xyz, dtype=np.float32), k=1, distance_upper_bound=radius_m)
        d = np.asarray(d, dtype=np.float64)
        d[d > radius_m] = np.inf
        return d, np.asarray(i, dtype=np.int64)
    if backend == "ckdtree":
        exact = cKDTree(np.asarray(b_xyz, dtype=np.float64))
        return exact.query(
            np.asarray(a_xyz, dtype=np.float64), k=1, distance_upper_bound=radius_m, workers=-1
        )
    raise LabelError(f"nearest-neighbour backend {backend!r}: use one of {NN_BACKENDS}.")


def plane_distances(
    b_xyz: np.ndarray, q_xyz: np.ndarray, test: SurfaceTest, tree: KDTree | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each query point: its distance (metres) along the normal of the plane fitted to its
    ``test.neighbours`` nearest points of ``b_xyz`` within ``test.search_m`` (inf where fewer than 3
    lie there), the level of detection there (metres) and the index of its nearest point (len(b_xyz)
    where none). Site-local coordinates; the fit is in float64 about the neighbours' mean. ``tree``:
    :func:`float32_tree` of ``b_xyz`` when already built."""
    k = max(3, min(test.neighbours, len(b_xyz)))
    tree = tree if tree is not None else float32_tree(b_xyz)
    d, i = tree.query(np.ascontiguousarray(q_xyz, dtype=np.float32), k=k, distance_upper_bound=test.search_m)
    d, i = np.asarray(d, np.float64).reshape(len(q_xyz), k), np.asarray(i, np.int64).reshape(len(q_xyz), k)
    valid = d <= test.search_m
    count = valid.sum(axis=1)
    dist = np.full(len(q_xyz), np.inf)
    lod = np.full(len(q_xyz), test.lod_floor_m)
    ok = np.flatnonzero(count >= 3)
    if len(ok):
        w = valid[ok].astype(np.float64)
        pts = np.asarray(np.asarray(b_xyz)[np.where(valid[ok], i[ok], 0)], np.float64)  # (m, k, 3)
        n = w.sum(axis=1)
        mean = (pts * w[..., None]).sum(axis=1) / n[:, None]
        centred = (pts - mean[:, None, :]) * w[..., None]
        cov = np.einsum("mki,mkj->mij", centred, centred) / n[:, None, None]
        vals, vecs = np.linalg.eigh(cov)  # ascending: the first vector is the plane's normal
        normal = vecs[:, :, 0]
        dist[ok] = np.abs(np.einsum("mi,mi->m", np.asarray(q_xyz, np.float64)[ok] - mean, normal))
        lod[ok] = np.maximum(test.lod_floor_m, test.lod_sigmas * np.sqrt(np.clip(vals[:, 0], 0.0, None)))
    first = np.where(valid[:, 0], i[:, 0], len(b_xyz))
    return dist, lod, first


# a plan grid of up to this many cells is looked up in a dense array (64 MiB of bool at most)
DENSE_CELLS = 1 << 26


def hidden_from_other(
    b_xyz: np.ndarray, q_xyz: np.ndarray, test: SurfaceTest
) -> tuple[np.ndarray, np.ndarray]:
    """Two (M,) bool arrays about the query points, from the other scene (``b_xyz``) in each query
    point's cell of a plan grid of ``test.search_m``: ``covered``, it has points there; ``hidden``, it
    has, and its lowest lies more than the level-of-detection floor above the query point (it could
    not have seen the point from above)."""
    cell = test.search_m
    q = np.asarray(q_xyz, np.float64)
    q_ij = np.floor(q[:, :2] / cell).astype(np.int64)
    lo, hi = q_ij.min(axis=0), q_ij.max(axis=0)
    span = hi - lo + 1
    b = np.asarray(b_xyz)
    # the other scene's points near the queries' extent first (a cell's margin: every point of their
    # cells is among them), so the floor below is not taken of the whole neighbourhood per call
    box_lo, box_hi = lo * cell - cell, (hi + 1) * cell + cell
    near = (b[:, 0] >= box_lo[0]) & (b[:, 0] <= box_hi[0]) & (b[:, 1] >= box_lo[1]) & (b[:, 1] <= box_hi[1])
    b = b[near]
    b_ij = np.floor(b[:, :2].astype(np.float64) / cell).astype(np.int64)
    # only the other scene's points in the queries' cells matter: a lookup over the queries' extent
    # picks them without sorting every point of the other scene
    within = ((b_ij >= lo) & (b_ij <= hi)).all(axis=1)
    q_key = (q_ij[:, 0] - lo[0]) * span[1] + (q_ij[:, 1] - lo[1])
    b_key = (b_ij[within, 0] - lo[0]) * span[1] + (b_ij[within, 1] - lo[1])
    b_z = b[within, 2].astype(np.float64)
    if int(span[0]) * int(span[1]) <= DENSE_CELLS:
        present = np.zeros(int(span[0]) * int(span[1]), dtype=bool)
        present[q_key] = True
        pick = present[b_key]
    else:
        pick = np.isin(b_key, np.unique(q_key))
    b_key, b_z = b_key[pick], b_z[pick]
    order = np.argsort(b_key, kind="stable")
    keys, starts = np.unique(b_key[order], return_index=True)
    lowest = np.minimum.reduceat(b_z[order], starts) if len(keys) else np.zeros(0)
    at = np.clip(np.searchsorted(keys, q_key), 0, max(len(keys) - 1, 0))
    if not len(keys):
        none = np.zeros(len(q_key), dtype=bool)
        return none, none.copy()
    has = keys[at] == q_key
    return has, has & (lowest[at] > q[:, 2] + test.lod_floor_m)


def class_within(
    b_xyz: np.ndarray,
    b_cls: np.ndarray,
    q_xyz: np.ndarray,
    q_cls: np.ndarray,
    radius_m: float,
    test: SurfaceTest,
    tree: KDTree | None = None,
) -> np.ndarray:
    """(M,) bool: whether any of each query point's ``test.neighbours`` nearest points of ``b_xyz``
    within ``radius_m`` has the query's class. Site-local metres; ``tree``: :func:`float32_tree` of
    ``b_xyz`` when already built."""
    k = max(1, min(test.neighbours, len(b_xyz)))
    tree = tree if tree is not None else float32_tree(b_xyz)
    d, i = tree.query(np.ascontiguousarray(q_xyz, dtype=np.float32), k=k, distance_upper_bound=radius_m)
    d, i = np.asarray(d, np.float64).reshape(len(q_xyz), k), np.asarray(i, np.int64).reshape(len(q_xyz), k)
    valid = d <= radius_m
    cls = np.asarray(b_cls)[np.where(valid, i, 0)]
    return (valid & (cls == np.asarray(q_cls)[:, None])).any(axis=1)


@dataclass(frozen=True)
class Matching:
    """How a point looks for its match in the other scene: the nearest-neighbour ``backend``
    (:data:`NN_BACKENDS`) and, for the surface rule, the :class:`SurfaceTest` (None: the nearest rule)."""

    backend: str = "pykdtree"
    surface: SurfaceTest | None = None


def change_flags(
    a_xyz: np.ndarray,
    a_cls: np.ndarray,
    b_xyz: np.ndarray,
    b_cls: np.ndarray,
    radius_m: float,
    ignored: np.ndarray,
    matching: Matching = Matching(),
    geometric: np.ndarray | None = None,
) -> np.ndarray:
    """Change of each point of A against B, (N,) uint8: 0 unchanged, 1 changed, 255 ignored.

    a_xyz (N, 3), b_xyz (M, 3): site-local metres (float32 or float64). a_cls, b_cls: uint8 site
    classes. ignored: (256,) bool lookup of ignored classes. A point of A is ignored when its class
    is; otherwise changed when B has no point of a non-ignored class within ``radius_m`` (with
    ``matching.surface``, when it is not on B's local surface either: the module docstring), or when the
    nearest such point has another class, unless either class is compared by geometry only
    (``geometric``: (256,) bool lookup, e.g. "unclassified"; all True: a class-agnostic rule).
    """
    out = np.full(len(a_xyz), IGNORED, dtype=np.uint8)
    live = ~ignored[a_cls]
    if not live.any():
        return out
    b_keep = ~ignored[b_cls]
    if not b_keep.any():
        out[live] = CHANGED
        return out
    # each selection once (copies of a million points or more), none when everything is kept
    b_kept = b_xyz if b_keep.all() else b_xyz[b_keep]
    b_classes = b_cls if b_keep.all() else b_cls[b_keep]
    a_pts = a_xyz if live.all() else a_xyz[live]
    a_classes = a_cls if live.all() else a_cls[live]
    tree = float32_tree(b_kept) if matching.backend == "pykdtree" else None
    dist, idx = nearest(b_kept, a_pts, radius_m, matching.backend, tree)
    found = np.isfinite(dist)
    uncovered = np.zeros(len(dist), dtype=bool)
    surface = matching.surface
    # the points looked at again: those the nearest test flags, and those it finds only far (the probe)
    again = None if surface is None else np.flatnonzero(~found | (dist > surface.probe_m))
    if surface is not None and again is not None and len(again):
        d, lod, first = plane_distances(b_kept, a_pts[again], surface, tree)
        near = found[again]  # found within the radius, but not near: changed when off the surface
        off = near & np.isfinite(d) & (d > np.maximum(lod, surface.offset_m))
        found[again[off]] = False
        again, d, lod, first = again[~near], d[~near], lod[~near], first[~near]
        on = d <= lod
        found[again[on]] = True
        idx[again[on]] = first[on]
        alone = np.flatnonzero(~np.isfinite(d))
        if len(alone):
            covered, unseen = hidden_from_other(b_kept, a_pts[again[alone]], surface)
            # nothing to compare with: unchanged from this side, whatever the classes say
            seen_not = again[alone[unseen]]
            found[seen_not] = True
            idx[seen_not] = -1
            # the other scene has nothing in the point's plan cell: it never covered the place
            uncovered[again[alone[~covered]]] = True
    same = np.zeros(len(dist), dtype=bool)
    compared = found & (idx >= 0)
    b_near, a_here = b_classes[idx[compared]], a_classes[compared]
    same[compared] = b_near == a_here
    if geometric is not None:
        same[compared] |= geometric[b_near] | geometric[a_here]
    if surface is not None:
        # the nearest point may be another object's (a worker beside the ground point, a wall's
        # foot): the class is compared with any of the other scene's points within the radius
        differ = np.flatnonzero(compared)[~same[compared]]
        if len(differ):
            same[differ] = class_within(
                b_kept, b_classes, a_pts[differ], a_classes[differ], radius_m, surface, tree
            )
    same[found & (idx < 0)] = True
    out[live] = np.where(uncovered, IGNORED, np.where(same, UNCHANGED, CHANGED))
    return out


def median_spacing(xyz: np.ndarray, max_points: int = 200_000, seed: int = 0) -> float:
    """Median nearest-neighbour distance (metres) of a cloud (a seeded subsample of the queries). The
    tree is pykdtree's in float64: the same distances as SciPy's cKDTree, built 2.7x faster (20 s on a
    25 M point tile at 8000 points/m2)."""
    from pykdtree.kdtree import KDTree

    pts = np.ascontiguousarray(xyz, dtype=np.float64)
    if len(pts) < 2:
        return float("nan")
    tree = KDTree(pts)
    rng = np.random.default_rng(seed)
    q = pts if len(pts) <= max_points else pts[rng.choice(len(pts), max_points, replace=False)]
    d, _ = tree.query(q, k=2)
    return float(np.median(d[:, 1]))
