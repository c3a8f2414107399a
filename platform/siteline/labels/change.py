"""3D change between two scenes (DESIGN.md §4): pure functions over site-local arrays."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from siteline.codes import CHANGED, UNCHANGED
from siteline.codes import IGNORE as IGNORED
from siteline.errors import LabelError

NN_BACKENDS = ("pykdtree", "ckdtree")


def nearest(
    b_xyz: np.ndarray, a_xyz: np.ndarray, radius_m: float, backend: str = "pykdtree"
) -> tuple[np.ndarray, np.ndarray]:
    """Distance to and index of each query's nearest point of ``b_xyz`` within ``radius_m`` (inf and
    an out-of-range index beyond it). pykdtree works in float32 site-local coordinates (the faster
    here, bench/release.py); ckdtree in float64 on every core."""
    if backend == "pykdtree":
        from pykdtree.kdtree import KDTree

        tree = KDTree(np.ascontiguousarray(b_xyz, dtype=np.float32))
        d, i = tree.query(np.ascontiguousarray(a_xyz, dtype=np.float32), k=1, distance_upper_bound=radius_m)
        d = np.asarray(d, dtype=np.float64)
        d[d > radius_m] = np.inf
        return d, np.asarray(i, dtype=np.int64)
    if backend == "ckdtree":
        tree = cKDTree(np.asarray(b_xyz, dtype=np.float64))
        return tree.query(np.asarray(a_xyz, dtype=np.float64), k=1, distance_upper_bound=radius_m, workers=-1)
    raise LabelError(f"nearest-neighbour backend {backend!r}: use one of {NN_BACKENDS}.")


def change_flags(
    a_xyz: np.ndarray,
    a_cls: np.ndarray,
    b_xyz: np.ndarray,
    b_cls: np.ndarray,
    radius_m: float,
    ignored: np.ndarray,
    backend: str = "pykdtree",
    geometric: np.ndarray | None = None,
) -> np.ndarray:
    """Change of each point of A against B, (N,) uint8: 0 unchanged, 1 changed, 255 ignored.

    a_xyz (N, 3), b_xyz (M, 3): site-local metres (float32 or float64). a_cls, b_cls: uint8 site
    classes. ignored: (256,) bool lookup of ignored classes. A point of A is ignored when its class
    is; otherwise changed when B has no point of a non-ignored class within ``radius_m``, or when the
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
    dist, idx = nearest(b_xyz[b_keep], a_xyz[live], radius_m, backend)
    found = np.isfinite(dist)
    same = np.zeros(len(dist), dtype=bool)
    b_near, a_live = b_cls[b_keep][idx[found]], a_cls[live][found]
    same[found] = b_near == a_live
    if geometric is not None:
        same[found] |= geometric[b_near] | geometric[a_live]
    out[live] = np.where(same, UNCHANGED, CHANGED)
    return out


def median_spacing(xyz: np.ndarray, max_points: int = 200_000, seed: int = 0) -> float:
    """Median nearest-neighbour distance (metres) of a cloud (a seeded subsample of the queries)."""
    pts = np.asarray(xyz, dtype=np.float64)
    if len(pts) < 2:
        return float("nan")
    tree = cKDTree(pts)
    rng = np.random.default_rng(seed)
    q = pts if len(pts) <= max_points else pts[rng.choice(len(pts), max_points, replace=False)]
    d, _ = tree.query(q, k=2)
    return float(np.median(d[:, 1]))
