"""Spatial coherence of 3D change: a change is a region, not a point.

Changed points are linked when they fall in the same or touching cells (26-neighbourhood) of a grid
of ``cell_m`` (twice the change radius in the label stage: points of one changed surface lie closer
than that, even on a thin, sparsely scanned one), and a region
of fewer than ``min_points`` points is taken back to unchanged: what the rules flag by chance on an
unchanged surface is a scatter of single points, a real change a connected surface. The smallest
change kept is therefore ``min_points`` points (``min_points`` / density square metres of surface).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

# the 13 cells that touch a cell and come after it in (i, j, k) order: with their mirror images, the
# 26 neighbours
_FORWARD = [(di, dj, dk) for di in (-1, 0, 1) for dj in (-1, 0, 1) for dk in (-1, 0, 1) if (di, dj, dk) > (0, 0, 0)]


def region_sizes(xyz: np.ndarray, cell_m: float) -> np.ndarray:
    """(N,) the number of points in each point's region (points linked through touching cells of
    ``cell_m`` metres). xyz: (N, 3) site-local metres."""
    n = len(xyz)
    if n == 0:
        return np.zeros(0, np.int64)
    ijk = np.floor(np.asarray(xyz, np.float64) / cell_m).astype(np.int64)
    ijk -= ijk.min(axis=0) - 1  # every cell and its neighbours at non-negative indices
    dims = ijk.max(axis=0) + 2
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    cells, inverse = np.unique(key, return_inverse=True)
    rows, cols = [], []
    for di, dj, dk in _FORWARD:
        other = cells + (di * dims[1] + dj) * dims[2] + dk
        at = np.searchsorted(cells, other)
        hit = at < len(cells)
        hit[hit] = cells[at[hit]] == other[hit]
        rows.append(np.flatnonzero(hit))
        cols.append(at[hit])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r), np.int8), (r, c)), shape=(len(cells), len(cells)))
    _, label = connected_components(graph, directed=False)
    per_cell = np.bincount(inverse, minlength=len(cells))
    sizes = np.bincount(label, weights=per_cell).astype(np.int64)
    return sizes[label[inverse]]


def small_regions(xyz: np.ndarray, cell_m: float, min_points: int) -> np.ndarray:
    """(N,) bool: the points whose region holds fewer than ``min_points`` points."""
    if min_points <= 1:
        return np.zeros(len(xyz), bool)
    return region_sizes(xyz, cell_m) < min_points
