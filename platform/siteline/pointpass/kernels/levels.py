"""Kernels of the level-of-detail assignment inside nested cubes (siteline.pointpass.lod)."""

from __future__ import annotations

import numpy as np

from siteline.pointpass.kernels import kernel
from siteline.pointpass.kernels.radix import run_starts


@kernel
def nested_keys(
    counts: np.ndarray, z0: int, cell0: int, fine: int, depth: int, order: np.ndarray
) -> np.ndarray:
    """(N,) int64 finest-cube key of the points taken in ``order`` (rank -> point): counts (N, 3) int32
    quanta from the tile origin, z from ``z0``, shifted onto a non-negative grid of level-0 cubes
    (edge ``cell0``); the finest cube (edge ``fine``) is the level-0 cube row-major (z, y, x) then
    the octree path below it, 3 bits a level over ``depth`` levels (x lowest), so every coarser
    cube is a contiguous run of keys."""
    n = counts.shape[0]
    low = np.full(3, np.int64(1) << 62)
    for p in range(n):
        low[0] = min(low[0], np.int64(counts[p, 0]))
        low[1] = min(low[1], np.int64(counts[p, 1]))
        low[2] = min(low[2], np.int64(counts[p, 2]) - z0)
    base = np.empty(3, np.int64)
    for a in range(3):
        base[a] = (low[a] // cell0) * cell0 if n else 0
    base[2] += z0
    span = np.ones(3, np.int64)  # level-0 cubes along each axis
    for p in range(n):
        for a in range(3):
            span[a] = max(span[a], (((np.int64(counts[p, a]) - base[a]) // fine) >> depth) + 1)
    by_point = np.empty(n, np.int64)
    for p in range(n):  # in point order (sequential reads), then gathered into rank order
        kx = (np.int64(counts[p, 0]) - base[0]) // fine
        ky = (np.int64(counts[p, 1]) - base[1]) // fine
        kz = (np.int64(counts[p, 2]) - base[2]) // fine
        path = np.int64(0)
        for b in range(depth):
            path |= (
                ((kx >> b) & 1) << (3 * b) | ((ky >> b) & 1) << (3 * b + 1) | ((kz >> b) & 1) << (3 * b + 2)
            )
        top = ((kz >> depth) * span[1] + (ky >> depth)) * span[0] + (kx >> depth)
        by_point[p] = top << (3 * depth) | path
    key = np.empty(n, np.int64)
    for r in range(n):
        key[r] = by_point[order[r]]
    return key


@kernel
def head_levels(key: np.ndarray, rank: np.ndarray, point: np.ndarray, last: int, levels: np.ndarray) -> None:
    """Assign levels 0 .. last - 1 (the rest: ``last``) into ``levels`` ((N,) uint8) of points sorted
    by (finest cube ``key``, ``rank``): ``point`` the point at each sorted position. In each cube of
    level L (a run of keys equal above the low 3 (last - 1 - L) bits) the lowest-ranked point no
    coarser level kept takes level L; it is always at the head of one of the cube's finest cubes,
    so each level looks at one head per finest cube."""
    n = key.shape[0]
    head = run_starts(key)  # each finest cube's next remaining point
    fine = head.shape[0]
    end = np.empty(fine, np.int64)
    end[: fine - 1] = head[1:]
    if fine:
        end[fine - 1] = n
    cube = key[head]
    for p in range(n):
        levels[p] = last
    for level in range(last):
        shift = 3 * (last - 1 - level)
        g = 0
        while g < fine:
            group = cube[g] >> shift
            best = -1
            h = g
            while h < fine and (cube[h] >> shift) == group:
                if head[h] < end[h] and (best < 0 or rank[head[h]] < rank[head[best]]):
                    best = h
                h += 1
            if best >= 0:
                levels[point[head[best]]] = level
                head[best] += 1
            g = h
