"""Level-of-detail assignment: a pure function over one tile's points."""

from __future__ import annotations

import numpy as np

from siteline.pointpass.kernels import levels as levels_kernels
from siteline.pointpass.kernels import radix
from siteline.pointpass.schema import voxel_key
from siteline.records.tiling import TileSpec


def _cell_counts(spec: TileSpec, levels: int) -> list[int]:
    return [max(1, int(round(spec.spacing(level) / spec.quantum_m))) for level in range(levels)]


def block_ranks(sizes: np.ndarray, seeds: list[list[int]]) -> np.ndarray:
    """The seeded rank order of points that come block after block (``sizes[k]`` points of block k,
    seeded ``seeds[k]``): (N,) the point at each rank, a permutation inside each block. A point's rank
    thus depends only on its block, so a tile levelled a few blocks at a time gets the same levels."""
    at = np.r_[0, np.cumsum(sizes)]
    return np.concatenate(
        [
            a + np.random.default_rng(s).permutation(int(n))
            for a, n, s in zip(at[:-1], sizes, seeds, strict=True)
        ]
        or [np.zeros(0, np.int64)]
    )


def assign_levels(counts: np.ndarray, spec: TileSpec, order: np.ndarray, z0: int | None = None) -> np.ndarray:
    """(N,) uint8 level of each point of one tile (or of whole level-0 cubes of it).

    counts: (N, 3) int32 quantised coordinates relative to the tile origin; order: the points in
    their seeded rank order (:func:`block_ranks`); z0: the tile's lowest z count (None: these
    points'). In rank order, level L keeps the first point of every occupied cube of edge
    ``spec.spacing(L)`` among points not kept by a lower level; the last level keeps all the rest.
    Cubes lie on a grid from the tile origin, z from z0 (a surface rests on the bottom of its cubes,
    not across two), so any set of whole level-0 cubes is levelled alike alone or with the rest of
    its tile. Every level is thus a spatially uniform subsample and levels partition the points.

    When the cubes nest (each level's edge is half the previous one, in whole quanta: the default
    spec), the points are sorted once by (cube path, rank), where every cube of every level is a
    contiguous run, and each level looks only at the next point of each finest cube
    (siteline.pointpass.kernels.levels); otherwise each level sorts its own cube keys.
    """
    n = len(counts)
    levels = np.full(n, 255, dtype=np.uint8)
    if n == 0:
        return levels
    last = spec.level_count - 1
    if last == 0:
        levels[:] = 0
        return levels
    cells = _cell_counts(spec, last)
    z0 = int(counts[:, 2].min()) if z0 is None else z0
    nested = all(cells[i] == cells[i + 1] * 2 for i in range(len(cells) - 1))
    if not nested:
        pts = counts.astype(np.int64)
        pts[:, 2] -= z0
        pts -= np.floor_divide(pts.min(axis=0), cells[0]) * cells[0]  # non-negative, on the same grid
        return _assign_by_sorting(pts, order, cells, last, levels)
    # finest-cube keys in rank order, sorted stably: by (finest cube, rank)
    key = levels_kernels.nested_keys(np.ascontiguousarray(counts), z0, cells[0], cells[-1], last - 1, order)
    rank = radix.radix_order(key)
    levels_kernels.head_levels(key[rank], rank, order[rank], last, levels)
    return levels


def _assign_by_sorting(
    pts: np.ndarray, order: np.ndarray, cells: list[int], last: int, levels: np.ndarray
) -> np.ndarray:
    remaining = order
    for level in range(last):
        if remaining.size == 0:
            return levels
        cell = cells[level]
        p = pts[remaining]
        key = voxel_key(
            np.floor_divide(p[:, 0], cell), np.floor_divide(p[:, 1], cell), np.floor_divide(p[:, 2], cell)
        )
        _, first = np.unique(key, return_index=True)  # first occurrence in the shuffled order
        levels[remaining[first]] = level
        keep = np.ones(remaining.size, dtype=bool)
        keep[first] = False
        remaining = remaining[keep]
    levels[remaining] = last
    return levels
