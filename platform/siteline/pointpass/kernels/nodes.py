"""Kernels of a tile's node plan: counting points per (level, finest cube) and placing each point
in its group's seeded slot (siteline.pointpass.nodes)."""

from __future__ import annotations

import numpy as np

from siteline.pointpass.kernels import cube_count_key, group_key, kernel, order_key, pack_cube
from siteline.pointpass.kernels.radix import radix_order, run_starts
from siteline.pointpass.schema import ORDER_BITS, Z_OFFSET


@kernel
def fine_cube(counts: np.ndarray, p: int, edge: int, depth: int) -> tuple[int, int, int]:
    """Point p's cube at depth ``depth`` (edge ``edge`` quanta): x and y clamped into the tile."""
    top = (1 << depth) - 1
    cx, cy, cz = counts[p, 0] // edge, counts[p, 1] // edge, counts[p, 2] // edge
    return min(max(cx, 0), top), min(max(cy, 0), top), cz


@kernel
def cube_rows(counts: np.ndarray, levels: np.ndarray, edge: int, depth: int) -> np.ndarray:
    """(M, 2) int64 rows (key, points) of each occupied (level, finest cube), by key: key = level << 48
    | (cube z + 2**20) << 2 depth | cube y << depth | cube x. An empty (0, 2) when a cube's z lies
    2**20 cubes or more from 0 (the caller refuses it)."""
    n = counts.shape[0]
    zlo, zhi = np.int64(1) << 62, -(np.int64(1) << 62)
    for p in range(n):
        cz = counts[p, 2] // edge
        zlo, zhi = min(zlo, cz), max(zhi, cz)
    if n and (zlo <= -Z_OFFSET or zhi >= Z_OFFSET):
        return np.zeros((0, 2), np.int64)
    zspan = zhi - zlo + 1
    compact = np.empty(n, np.int64)  # (level, z, y, x) in the key's order, from 0
    for p in range(n):
        cx, cy, cz = fine_cube(counts, p, edge, depth)
        compact[p] = ((levels[p] * zspan + cz - zlo) << (2 * depth)) | cy << depth | cx
    order = radix_order(compact)
    first = run_starts(compact[order])
    m = first.shape[0]
    rows = np.empty((m, 2), np.int64)
    for r in range(m):
        p = order[first[r]]
        cx, cy, cz = fine_cube(counts, p, edge, depth)
        rows[r, 0] = cube_count_key(np.int64(levels[p]), cx, cy, cz, depth)
        rows[r, 1] = (first[r + 1] if r + 1 < m else n) - first[r]
    return rows


@kernel
def _mix(x: np.uint64) -> np.uint64:
    """splitmix64's output function: a well-mixed 64-bit value of ``x``."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@kernel
def group_points(
    counts: np.ndarray,
    levels: np.ndarray,
    grid: tuple[int, int, int, int],
    band_of_level: np.ndarray,
    depth_of_band: np.ndarray,
    key: np.ndarray,
) -> np.ndarray:
    """(N,) the group of each of a batch of a tile's points (counts (N, 3), levels (N,)): the row of
    ``key`` (sorted group keys: band, cube at the band's depth, level) it belongs to; ``grid``: (finest
    cube edge in quanta, finest depth, lowest cube z, bits of a cube). -1 everywhere when a point has
    no group."""
    edge, depth, z0, cube_bits = grid
    n, groups = counts.shape[0], key.shape[0]
    group = np.empty(n, np.int64)
    for p in range(n):
        lv = levels[p]
        band = band_of_level[lv]
        d = depth_of_band[band]
        cx, cy, cz = fine_cube(counts, p, edge, depth)
        s = depth - d
        k = group_key(band, pack_cube(cx >> s, cy >> s, (cz >> s) - z0, d), lv, cube_bits)
        g = np.searchsorted(key, k)
        if g >= groups or key[g] != k:
            return np.full(n, -1, np.int64)
        group[p] = g
    return group


@kernel
def slot_points(
    group: np.ndarray, start: np.ndarray, size: np.ndarray, seen: np.ndarray, seed: int, shuffle: bool
) -> np.ndarray:
    """(N,) array position of each point of a batch whose groups are ``group`` (:func:`group_points`),
    in the tile's order: the next of its group's slots (group g's ``size[g]`` slots start at
    ``start[g]``), in a permutation seeded by (seed, group) when ``shuffle`` (the Fisher-Yates shuffle
    of a splitmix64 stream), in order otherwise; ``seen`` (per group, slots earlier batches took) is
    updated. -1 everywhere when a group would take more slots than it has."""
    n, groups = group.shape[0], start.shape[0]
    taken = np.zeros(groups, np.int64)
    for p in range(n):
        taken[group[p]] += 1
    for g in range(groups):
        if seen[g] + taken[g] > size[g]:
            return np.full(n, -1, np.int64)
    first = np.zeros(groups + 1, np.int64)  # each group's slots in ``slots``
    for g in range(groups):
        first[g + 1] = first[g] + taken[g]
    slots = np.empty(n, np.int64)
    perm = np.empty(size.max() if groups else 0, np.int64)
    for g in range(groups):
        if taken[g] == 0:
            continue
        a, m = seen[g], size[g]
        if shuffle:
            for i in range(m):
                perm[i] = i
            state = _mix(np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(g))
            for i in range(a + taken[g]):
                state += np.uint64(0x9E3779B97F4A7C15)
                j = i + np.int64(_mix(state) % np.uint64(m - i))
                perm[i], perm[j] = perm[j], perm[i]
            for i in range(taken[g]):
                slots[first[g] + i] = start[g] + perm[a + i]
        else:
            for i in range(taken[g]):
                slots[first[g] + i] = start[g] + a + i
        seen[g] += taken[g]
    where = np.empty(n, np.int64)
    for p in range(n):
        g = group[p]
        where[p] = slots[first[g]]
        first[g] += 1
    return where


_SMALL = 64  # groups up to this many points are sorted by insertion, not by counting


@kernel
def order_in_groups(counts: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """(N,) int64 order that sorts each group of points (rows ``bounds[g]:bounds[g + 1]`` of counts
    (N, 3)) by their node-order key (:func:`siteline.pointpass.schema.order_key`), ties in their order (a
    stable counting sort): ``rows[order]`` is in node order."""
    n = counts.shape[0]
    key = np.empty(n, np.int64)
    for p in range(n):
        key[p] = order_key(counts[p, 0], counts[p, 1], counts[p, 2])
    order = np.arange(n)
    count = np.empty((1 << 3 * ORDER_BITS) + 1, np.int64)
    for g in range(bounds.shape[0] - 1):
        a, b = bounds[g], bounds[g + 1]
        if b - a <= _SMALL:
            for i in range(a + 1, b):
                j = i
                while j > a and key[order[j - 1]] > key[i]:
                    order[j] = order[j - 1]
                    j -= 1
                order[j] = i
            continue
        count[:] = 0
        for p in range(a, b):
            count[key[p] + 1] += 1
        for d in range(count.shape[0] - 1):
            count[d + 1] += count[d]
        for p in range(a, b):
            order[a + count[key[p]]] = p
            count[key[p]] += 1
    return order
