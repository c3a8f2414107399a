"""Compiled loops of the adaptive rule's surface tests (siteline.labels.change): per query point, small
work over its k nearest points of the other scene, where numpy would build (points x planes x k)
temporaries (a pair at 1000 points/m2 looks again at a million points or more). Site-local metres,
float64."""

from __future__ import annotations

import math

import numpy as np

from siteline.pointpass import kernel


@kernel
def spacing_of(rel: np.ndarray, use: np.ndarray) -> float:
    """The median, over the points ``rel`` (k, 3) where ``use`` (k,), of the distance from each to the
    nearest other of them (metres; NaN with fewer than two)."""
    k = rel.shape[0]
    nn = np.empty(k)
    n = 0
    for a in range(k):
        if not use[a]:
            continue
        best = math.inf
        for b in range(k):
            if b == a or not use[b]:
                continue
            d2 = (rel[a, 0] - rel[b, 0]) ** 2 + (rel[a, 1] - rel[b, 1]) ** 2 + (rel[a, 2] - rel[b, 2]) ** 2
            best = min(best, d2)
        if best < math.inf:
            nn[n] = math.sqrt(best)
            n += 1
    return np.median(nn[:n]) if n else math.nan


@kernel
def own_spacings(pts: np.ndarray, valid: np.ndarray, out: np.ndarray) -> None:
    """Per row of ``pts`` (m, k, 3), :func:`spacing_of` its ``valid`` (m, k) points, into ``out`` (m,)."""
    for r in range(pts.shape[0]):
        out[r] = spacing_of(pts[r], valid[r])


@kernel
def planes_through(
    q: np.ndarray, pts: np.ndarray, valid: np.ndarray, anchors: int, limits: np.ndarray, out: np.ndarray
) -> None:
    """Per query point ``q`` (m, 3) and its neighbours ``pts`` (m, k, 3) (those ``valid`` (m, k)):
    whether some plane through the point and two of its neighbours, the first one of its first
    ``anchors``, holds ``min_fit`` or more of them within ``tol_m``, the point lying among those (its
    offset along the plane from their mean within ``surround`` x their RMS spread, its nearest of
    them within ``gap`` x their own spacing, :func:`spacing_of`); ``limits``: (tol_m, min_fit,
    surround, gap) float64. The first plane with the most of them is the one judged. Into ``out`` (m,)
    bool."""
    tol_m, min_fit, surround, gap = limits[0], limits[1], limits[2], limits[3]
    m, k = valid.shape
    rel = np.empty((k, 3))
    inl = np.empty(k, np.bool_)
    for r in range(m):
        out[r] = False
        for a in range(k):
            for c in range(3):
                rel[a, c] = pts[r, a, c] - q[r, c]
        best_n = 0
        bx = by = bz = 0.0
        for a in range(min(anchors, k)):
            if not valid[r, a]:
                continue
            la = math.sqrt(rel[a, 0] ** 2 + rel[a, 1] ** 2 + rel[a, 2] ** 2)
            for j in range(a + 1, k):
                if not valid[r, j]:
                    continue
                nx = rel[a, 1] * rel[j, 2] - rel[a, 2] * rel[j, 1]
                ny = rel[a, 2] * rel[j, 0] - rel[a, 0] * rel[j, 2]
                nz = rel[a, 0] * rel[j, 1] - rel[a, 1] * rel[j, 0]
                norm = math.sqrt(nx * nx + ny * ny + nz * nz)
                lj = math.sqrt(rel[j, 0] ** 2 + rel[j, 1] ** 2 + rel[j, 2] ** 2)
                if norm <= 1e-3 * la * lj:  # in line with the point: no plane
                    continue
                nx, ny, nz = nx / norm, ny / norm, nz / norm
                count = 0
                for b in range(k):
                    if valid[r, b] and abs(nx * rel[b, 0] + ny * rel[b, 1] + nz * rel[b, 2]) <= tol_m:
                        count += 1
                if count > best_n:
                    best_n, bx, by, bz = count, nx, ny, nz
        if best_n < min_fit:
            continue
        mx = my = mz = 0.0
        nearest = math.inf
        for b in range(k):
            inl[b] = valid[r, b] and abs(bx * rel[b, 0] + by * rel[b, 1] + bz * rel[b, 2]) <= tol_m
            if inl[b]:
                mx += rel[b, 0]
                my += rel[b, 1]
                mz += rel[b, 2]
                nearest = min(nearest, math.sqrt(rel[b, 0] ** 2 + rel[b, 1] ** 2 + rel[b, 2] ** 2))
        mx, my, mz = mx / best_n, my / best_n, mz / best_n
        var = 0.0
        for b in range(k):
            if inl[b]:
                var += (rel[b, 0] - mx) ** 2 + (rel[b, 1] - my) ** 2 + (rel[b, 2] - mz) ** 2
        spread = math.sqrt(var / best_n)
        along = mx * bx + my * by + mz * bz  # the point is at the origin
        offset = math.sqrt((mx - along * bx) ** 2 + (my - along * by) ** 2 + (mz - along * bz) ** 2)
        if offset > surround * spread:
            continue
        if gap < math.inf and not nearest <= gap * spacing_of(rel, inl):
            continue
        out[r] = True


@kernel
def plan_cells(
    b_ij: np.ndarray,
    b_z: np.ndarray,
    b_ground: np.ndarray,
    q_ij: np.ndarray,
    q_z: np.ndarray,
    shape: tuple[int, int],
    limits: tuple[float, float],
    out: np.ndarray,
) -> None:
    """What the other scene holds in each query's cell of a plan grid of ``shape`` cells (its points'
    and the queries' cells ``*_ij`` (n, 2) int64 (row, column), inside the grid with a cell to spare
    around every query): per query, into ``out`` (M, 4) bool, whether the cell holds points (covered),
    whether its lowest lies more than ``floor_m`` above the query (hidden), whether its highest lies no
    lower than ``floor_m`` below it or the highest of the 8 cells around more than ``over_m`` above it
    (above), and whether a hidden query's lowest point is ``b_ground`` (buried); ``limits``:
    (floor_m, over_m). One pass over the points, one over the queries."""
    floor_m, over_m = limits
    b_i, b_j, q_i, q_j = b_ij[:, 0], b_ij[:, 1], q_ij[:, 0], q_ij[:, 1]
    ni, nj = shape
    lowest = np.full(ni * nj, np.inf)
    highest = np.full(ni * nj, -np.inf)
    low_ground = np.zeros(ni * nj, np.bool_)
    for p in range(len(b_z)):
        c = b_i[p] * nj + b_j[p]
        z = b_z[p]
        if z < lowest[c]:
            lowest[c] = z
            low_ground[c] = b_ground[p]
        if z > highest[c]:
            highest[c] = z
    for q in range(len(q_z)):
        c = q_i[q] * nj + q_j[q]
        z = q_z[q]
        has = lowest[c] < np.inf
        hidden = has and lowest[c] > z + floor_m
        top = -np.inf
        for di in range(-1, 2):
            for dj in range(-1, 2):
                top = max(top, highest[(q_i[q] + di) * nj + q_j[q] + dj])
        out[q, 0] = has
        out[q, 1] = hidden
        out[q, 2] = has and (highest[c] >= z - floor_m or top > z + over_m)
        out[q, 3] = hidden and low_ground[c]
