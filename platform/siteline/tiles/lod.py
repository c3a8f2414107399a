"""Level-of-detail assignment: a pure function over one tile's points."""

from __future__ import annotations

import numpy as np

from siteline.tiles.layout import TileSpec, level_count


def assign_levels(counts: np.ndarray, spec: TileSpec, seed: int) -> np.ndarray:
    """(N,) uint8 level of each point of one tile.

    counts: (N, 3) int32 quantised coordinates relative to the tile origin. In a seeded random order,
    level L keeps the first point of every occupied cube of edge ``spec.spacing(L)`` among points not
    kept by a lower level; the last level keeps all the rest. Every level is thus a spatially uniform
    subsample and levels partition the points.
    """
    n = len(counts)
    levels = np.full(n, 255, dtype=np.uint8)
    if n == 0:
        return levels
    order = np.random.default_rng(seed).permutation(n)
    remaining = order
    pts = counts.astype(np.int64)
    zmin = pts[:, 2].min()
    last = level_count(spec) - 1
    for level in range(last + 1):
        if remaining.size == 0:
            break
        if level == last:
            levels[remaining] = level
            break
        cell = max(1, int(round(spec.spacing(level) / spec.quantum_m)))
        p = pts[remaining]
        kx = np.floor_divide(p[:, 0], cell)
        ky = np.floor_divide(p[:, 1], cell)
        kz = np.floor_divide(p[:, 2] - zmin, cell)
        key = (kx + (1 << 20)) | ((ky + (1 << 20)) << 21) | (kz << 42)
        _, first = np.unique(key, return_index=True)  # first occurrence in the shuffled order
        chosen = remaining[first]
        levels[chosen] = level
        keep = np.ones(remaining.size, dtype=bool)
        keep[first] = False
        remaining = remaining[keep]
    return levels
