"""Spatial coherence of 3D change: a change is a region, not a point.

Changed points are linked when they fall in the same or touching cells (26-neighbourhood) of a grid
of ``cell_m`` (twice the change radius in the label stage: points of one changed surface lie closer
than that, even on a thin, sparsely scanned one), and a region
of fewer than ``min_points`` points is taken back to unchanged: what the rules flag by chance on an
unchanged surface is a scatter of single points, a real change a connected surface. The smallest
change kept is therefore ``min_points`` points (``min_points`` / density square metres of surface).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from siteline.errors import LabelError

# the 13 cells that touch a cell and come after it in (i, j, k) order: with their mirror images, the
# 26 neighbours
_FORWARD = [
    (di, dj, dk) for di in (-1, 0, 1) for dj in (-1, 0, 1) for dk in (-1, 0, 1) if (di, dj, dk) > (0, 0, 0)
]


@dataclass(frozen=True)
class RegionRule:
    """How the label stage takes chance flags back: changed regions of fewer than ``min_points``
    points become unchanged (1 keeps every point); with ``sparse``, a sparse surface's changed samples
    (farther apart than the cells link) are kept whole where most of its samples around changed
    (siteline.labels.store)."""

    min_points: int = 1
    sparse: bool = False


# what a point that makes its region whole adds to its cell's count: more than any min_points
_WHOLE = 1 << 32


def region_sizes(xyz: np.ndarray, cell_m: float) -> np.ndarray:
    """(N,) the number of points in each point's region (points linked through touching cells of
    ``cell_m`` metres). xyz: (N, 3) site-local metres."""
    if len(xyz) == 0:
        return np.zeros(0, np.int64)
    cells, inverse, counts = _cells_of(xyz, cell_m)
    return cell_region_sizes(cells, counts)[inverse]


def small_regions(xyz: np.ndarray, cell_m: float, min_points: int) -> np.ndarray:
    """(N,) bool: the points whose region holds fewer than ``min_points`` points."""
    if min_points <= 1:
        return np.zeros(len(xyz), bool)
    return region_sizes(xyz, cell_m) < min_points


def _keys(ijk: np.ndarray, lo: np.ndarray, dims: np.ndarray) -> np.ndarray:
    """int64 keys of (N, 3) cell indices in the box of ``dims`` cells from ``lo``, ordered as the cells."""
    if float(dims[0]) * float(dims[1]) * float(dims[2]) >= 2.0**62:
        raise LabelError(
            f"changed points span {dims.tolist()} region cells: too many to number; label with a larger radius."
        )
    rel = ijk - lo
    return (rel[:, 0] * dims[1] + rel[:, 1]) * dims[2] + rel[:, 2]


def _pack(ijk: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_keys` of (N, 3) cell indices in their own box, with the box (:func:`_unpack`)."""
    lo = ijk.min(axis=0)
    dims = ijk.max(axis=0) - lo + 1
    return _keys(ijk, lo, dims), lo, dims


def _unpack(keys: np.ndarray, lo: np.ndarray, dims: np.ndarray) -> np.ndarray:
    k = keys % dims[2]
    ij = keys // dims[2]
    return np.stack([ij // dims[1], ij % dims[1], k], axis=1) + lo


def _cells_of(xyz: np.ndarray, cell_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distinct grid cells of ``xyz`` ((C, 3) int64 indices of ``cell_m`` metres), each point's
    cell (N,) and each cell's points (C,)."""
    ijk = np.floor(np.asarray(xyz, np.float64) / cell_m).astype(np.int64)
    keys, lo, dims = _pack(ijk)
    del ijk
    uniq, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    return _unpack(uniq, lo, dims), inverse, counts


def region_ids(xyz: np.ndarray, cell_m: float) -> np.ndarray:
    """(N,) int64 the region of each point (points linked through touching cells of ``cell_m``
    metres), numbered 0.. by size, the largest first (ties by their first point's order).
    xyz: (N, 3) site-local metres."""
    if len(xyz) == 0:
        return np.zeros(0, np.int64)
    cells, inverse, counts = _cells_of(xyz, cell_m)
    label = cell_regions(cells)[inverse]
    sizes = np.bincount(label)
    first = np.full(len(sizes), len(label))
    np.minimum.at(first, label, np.arange(len(label)))
    rank = np.empty(len(sizes), np.int64)
    rank[np.lexsort((first, -sizes))] = np.arange(len(sizes))
    return rank[label]


def _padded_keys(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_keys` of (N, 3) cell indices in their box grown by a cell each way (every cell and its
    neighbours at non-negative indices), with the box's dims: a neighbour (di, dj, dk) of key k is
    ``k + (di dims[1] + dj) dims[2] + dk``."""
    lo = cells.min(axis=0) - 1
    dims = cells.max(axis=0) - lo + 2
    return _keys(cells, lo, dims), dims


def points_near(xyz: np.ndarray, of: np.ndarray, cell_m: float) -> np.ndarray:
    """(K,) int64 positions of the points ``xyz`` ((N, 3) metres) in the cells of ``cell_m`` that hold a
    point ``of`` ((M,) positions) or touch one (26 around)."""
    key, dims = _padded_keys(np.floor(np.asarray(xyz) / cell_m).astype(np.int64))  # in xyz's own precision
    steps = np.array([(di * dims[1] + dj) * dims[2] + dk for di, dj, dk in [(0, 0, 0), *_FORWARD]])
    steps = np.r_[steps, -steps[1:]]
    return np.flatnonzero(np.isin(key, np.unique((key[of][:, None] + steps[None, :]).ravel())))


def cell_regions(cells: np.ndarray) -> np.ndarray:
    """(C,) the region (a connected-component number) of each of ``cells`` ((C, 3) distinct int64
    cell indices), cells linked when they touch (26-neighbourhood)."""
    key, dims = _padded_keys(cells)
    order = np.argsort(key)
    key = key[order]
    rows, cols = [], []
    for di, dj, dk in _FORWARD:
        other = key + (di * dims[1] + dj) * dims[2] + dk
        at = np.searchsorted(key, other)
        hit = at < len(key)
        hit[hit] = key[at[hit]] == other[hit]
        rows.append(np.flatnonzero(hit))
        cols.append(at[hit])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r), np.int8), (r, c)), shape=(len(key), len(key)))
    _, label = connected_components(graph, directed=False)
    out = np.empty(len(cells), np.int64)
    out[order] = label
    return out


def cell_region_sizes(cells: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(C,) the points in the region of each of ``cells`` ((C, 3) distinct int64 cell indices holding
    ``counts`` points each), cells linked when they touch (26-neighbourhood)."""
    label = cell_regions(cells)
    return np.bincount(label, weights=counts).astype(np.int64)[label]


class RegionCells:
    """Changed points gathered part by part (a tile's) as the grid cells of ``cell_m`` metres they
    fall in: each part keeps its cells and, per point, which of them holds it (4 bytes a point, where
    the points' xyz took 12; at 8000 points/m2 a cell holds tens of points). :meth:`small` then finds
    the regions from the cells alone: the same as :func:`small_regions` of all the parts' points."""

    def __init__(self, cell_m: float) -> None:
        self.cell_m = cell_m
        self._cells: list[np.ndarray] = []
        self._counts: list[np.ndarray] = []
        self._inverse: list[np.ndarray] = []

    def add(self, xyz: np.ndarray, whole: np.ndarray | None = None) -> None:
        """The next part's changed points, (N, 3) site-local metres; ``whole``: (N,) bool, points that
        make a region whole on their own (a sparse surface's, whose samples lie farther apart than
        the cells link: a pole's), so their region is never small."""
        if len(xyz) == 0:
            cells, inverse, counts = np.zeros((0, 3), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
        else:
            cells, inverse, counts = _cells_of(xyz, self.cell_m)
            if whole is not None and whole.any():
                counts = counts + np.bincount(inverse[whole], minlength=len(counts)) * _WHOLE
        self._cells.append(cells)
        self._counts.append(counts)
        self._inverse.append(inverse.astype(np.int32))

    def small(self, min_points: int) -> list[np.ndarray]:
        """Per part, in the order added: (N,) bool, its points whose region holds fewer than
        ``min_points`` points of all parts."""
        if min_points <= 1 or not any(len(c) for c in self._cells):
            return [np.zeros(len(inv), bool) for inv in self._inverse]
        cells = np.concatenate(self._cells)
        keys, lo, dims = _pack(cells)
        uniq, merged = np.unique(keys, return_inverse=True)  # a cell shared by two parts is one cell
        counts = np.bincount(merged, weights=np.concatenate(self._counts), minlength=len(uniq)).astype(
            np.int64
        )
        small_cell = cell_region_sizes(_unpack(uniq, lo, dims), counts)[merged] < min_points
        out, start = [], 0
        for part, inverse in zip(self._cells, self._inverse, strict=True):
            out.append(small_cell[start : start + len(part)][inverse])
            start += len(part)
        return out
