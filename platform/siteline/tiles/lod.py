"""Level-of-detail assignment: a pure function over one tile's points."""

from __future__ import annotations

import numpy as np

from siteline.records.tiling import TileSpec
from siteline.sorting import sort_by_key
from siteline.tiles.layout import level_count

_BIG = np.iinfo(np.int64).max


def _spread3(v: np.ndarray) -> np.ndarray:
    """Spread the low 21 bits of v so that two zero bits separate each (Morton interleaving)."""
    v = v.astype(np.uint64) & np.uint64(0x1FFFFF)
    v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    v = (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)
    return v


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
    (:func:`_assign_nested`); otherwise each level sorts its own cube keys.
    """
    n = len(counts)
    levels = np.full(n, 255, dtype=np.uint8)
    if n == 0:
        return levels
    last = level_count(spec) - 1
    if last == 0:
        levels[:] = 0
        return levels
    cells = _cell_counts(spec, last)
    pts = counts.astype(np.int64)
    pts[:, 2] -= pts[:, 2].min() if z0 is None else z0
    pts -= np.floor_divide(pts.min(axis=0), cells[0]) * cells[0]  # non-negative, on the same grid
    nested = all(cells[i] == cells[i + 1] * 2 for i in range(len(cells) - 1))
    if not nested:
        return _assign_by_sorting(pts, order, cells, last, levels)
    return _assign_nested(_nested_key(pts, cells[-1], last - 1), order, last, levels)


def _nested_key(pts: np.ndarray, fine: int, depth: int) -> np.ndarray:
    """(N,) int64 key of each point's finest cube (edge ``fine`` quanta) in which the cube of every
    coarser level is a contiguous run: the level-0 cube (edge ``fine * 2**depth``) in row-major order,
    then the octree path below it, 3 bits a level (a Morton code of the low ``depth`` bits)."""
    k = pts >> (fine.bit_length() - 1) if fine & (fine - 1) == 0 else np.floor_divide(pts, fine)
    top = k >> depth
    span = top.max(axis=0) + 1
    lut = _spread3(np.arange(1 << depth)).astype(np.int64)
    low = k & ((1 << depth) - 1)
    path = lut[low[:, 0]] | lut[low[:, 1]] << 1 | lut[low[:, 2]] << 2
    return ((top[:, 2] * span[1] + top[:, 1]) * span[0] + top[:, 0]) << (3 * depth) | path


def _assign_nested(cube_key: np.ndarray, order: np.ndarray, last: int, levels: np.ndarray) -> np.ndarray:
    """Levels by nested cubes (``cube_key``: :func:`_nested_key`): points sorted by (finest cube,
    random rank), so a cube of every level is
    a contiguous run of finest cubes and each finest cube's points are in rank order. A level's
    winner in a cube is the lowest-ranked remaining point, always at the head of one of its finest
    cubes, so each level works on one head per finest cube, not on every point."""
    n = len(cube_key)
    rank = np.empty(n, np.int64)
    rank[order] = np.arange(n)
    m_sorted, s_rank = sort_by_key(cube_key, rank)
    point = order[s_rank]  # the point at each sorted position (order: rank -> point)
    new = np.ones(n, dtype=bool)
    new[1:] = m_sorted[1:] != m_sorted[:-1]
    head = np.flatnonzero(new)  # each finest cube's next remaining point
    end = np.r_[head[1:], n]
    cube_fine = m_sorted[head]
    for level in range(last):
        key = cube_fine >> (3 * (last - 1 - level))
        starts = np.r_[0, np.flatnonzero(key[1:] != key[:-1]) + 1]
        alive = head < end
        head_rank = np.where(alive, s_rank[np.minimum(head, n - 1)], _BIG)
        seg_min = np.minimum.reduceat(head_rank, starts)
        win = (head_rank == np.repeat(seg_min, np.diff(np.r_[starts, len(key)]))) & alive
        levels[point[head[win]]] = level
        head[win] += 1
    levels[levels == 255] = last
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
        key = (
            (np.floor_divide(p[:, 0], cell) + (1 << 20))
            | ((np.floor_divide(p[:, 1], cell) + (1 << 20)) << 21)
            | (np.floor_divide(p[:, 2], cell) << 42)
        )
        _, first = np.unique(key, return_index=True)  # first occurrence in the shuffled order
        levels[remaining[first]] = level
        keep = np.ones(remaining.size, dtype=bool)
        keep[first] = False
        remaining = remaining[keep]
    levels[remaining] = last
    return levels
