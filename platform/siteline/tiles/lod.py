"""Level-of-detail assignment: a pure function over one tile's points."""

from __future__ import annotations

import numpy as np

from siteline.records.tiling import TileSpec
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


def assign_levels(counts: np.ndarray, spec: TileSpec, seed: int) -> np.ndarray:
    """(N,) uint8 level of each point of one tile.

    counts: (N, 3) int32 quantised coordinates relative to the tile origin. In a seeded random order,
    level L keeps the first point of every occupied cube of edge ``spec.spacing(L)`` among points not
    kept by a lower level; the last level keeps all the rest. Every level is thus a spatially uniform
    subsample and levels partition the points.

    When the cubes nest (each level's edge is half the previous one, in whole quanta: the default
    spec), the points are sorted once in Morton order, where every cube of every level is a
    contiguous run, and each level is a segmented minimum over those runs; otherwise each level sorts
    its own cube keys.
    """
    n = len(counts)
    levels = np.full(n, 255, dtype=np.uint8)
    if n == 0:
        return levels
    last = level_count(spec) - 1
    order = np.random.default_rng(seed).permutation(n)
    pts = counts.astype(np.int64)
    pts = pts - np.array([0, 0, pts[:, 2].min()])
    cells = _cell_counts(spec, last)
    fine = cells[-1] if cells else 1
    nested = all(cells[i] == cells[i + 1] * 2 for i in range(len(cells) - 1))
    k = np.floor_divide(pts, fine) if cells else pts
    if last == 0:
        levels[:] = 0
        return levels
    if not nested or k.min() < 0 or k.max() >= 2**21:
        return _assign_by_sorting(pts, order, cells, last, levels)
    rank = np.empty(n, np.int64)
    rank[order] = np.arange(n)
    morton = _spread3(k[:, 0]) | (_spread3(k[:, 1]) << np.uint64(1)) | (_spread3(k[:, 2]) << np.uint64(2))
    srt = np.argsort(morton, kind="stable")
    m_sorted = morton[srt]
    masked = rank[srt]
    for level in range(last):
        key = m_sorted >> np.uint64(3 * (last - 1 - level))
        starts = np.r_[0, np.flatnonzero(key[1:] != key[:-1]) + 1]
        seg_min = np.minimum.reduceat(masked, starts)
        seg_of = np.repeat(np.arange(len(starts)), np.diff(np.r_[starts, n]))
        win = (masked == seg_min[seg_of]) & (masked != _BIG)
        levels[srt[win]] = level
        masked = np.where(win, _BIG, masked)
    levels[srt[masked != _BIG]] = last
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
