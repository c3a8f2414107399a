"""Kernels of the one pass over a point cloud: a LAS chunk's coordinates and colour, checking
site-local points and cutting a chunk into tile runs (siteline.pointpass.lasio, siteline.pointpass.partition,
siteline.pointpass.sitestream)."""

from __future__ import annotations

from typing import Any

import numpy as np

from siteline.pointpass.kernels import kernel
from siteline.pointpass.schema import COUNT_LIMIT


@kernel
def scaled_xyz(
    x: np.ndarray, y: np.ndarray, z: np.ndarray, scale: np.ndarray, offset: np.ndarray
) -> np.ndarray:
    """(N, 3) float64 coordinates of a LAS chunk's (N,) integer counts X, Y, Z: ``count * scale +
    offset`` per axis (laspy's arithmetic, bit for bit), in one pass."""
    out = np.empty((x.shape[0], 3))
    for p in range(x.shape[0]):
        out[p, 0] = x[p] * scale[0] + offset[0]
        out[p, 1] = y[p] * scale[1] + offset[1]
        out[p, 2] = z[p] * scale[2] + offset[2]
    return out


@kernel
def colour_u8(red: np.ndarray, green: np.ndarray, blue: np.ndarray, shift: int) -> np.ndarray:
    """(N, 3) uint8 colour of a LAS chunk's (N,) uint16 channels: the low byte of each value shifted
    right by ``shift`` (8 for true 16-bit colour, 0 for 0-255 stored in 16-bit fields)."""
    out = np.empty((red.shape[0], 3), np.uint8)
    for p in range(red.shape[0]):
        out[p, 0] = (red[p] >> shift) & 0xFF
        out[p, 1] = (green[p] >> shift) & 0xFF
        out[p, 2] = (blue[p] >> shift) & 0xFF
    return out


@kernel
def bounds(local: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Per axis the lowest and highest of (N, 3) float64 points and how many points have a
    non-finite coordinate (those are left out of the bounds)."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    bad = 0
    for p in range(local.shape[0]):
        x, y, z = local[p, 0], local[p, 1], local[p, 2]
        if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(z)):
            bad += 1
            continue
        lo[0], hi[0] = min(lo[0], x), max(hi[0], x)
        lo[1], hi[1] = min(lo[1], y), max(hi[1], y)
        lo[2], hi[2] = min(lo[2], z), max(hi[2], z)
    return lo, hi, bad


@kernel
def tile_codes(
    local: np.ndarray,
    tile_m: float,
    quantum_m: float,
    edge: int,
    side: int,
    counts: np.ndarray,
    code: np.ndarray,
) -> tuple[Any, Any, Any, float]:
    """Quantise a chunk's (N, 3) float64 site-local points into ``counts`` ((N, 3) int32 quanta from
    each point's tile origin, z from 0) and give each its ``code`` (N,): its tile, row-major over the
    chunk's tiles, times ``side**2``, plus its block ``by * side + bx`` (counts floored by ``edge``,
    clamped into the tile). Returns the chunk's lowest tile (i, j), its tiles along j and the largest
    absolute count (the caller refuses one that overflows int32)."""
    n = local.shape[0]
    inv_t, inv_q = 1.0 / tile_m, 1.0 / quantum_m
    lo_i = lo_j = np.int64(1) << 62
    hi_j = -lo_j
    for p in range(n):
        i, j = np.int64(np.floor(local[p, 0] * inv_t)), np.int64(np.floor(local[p, 1] * inv_t))
        lo_i, lo_j, hi_j = min(lo_i, i), min(lo_j, j), max(hi_j, j)
    span_j = hi_j - lo_j + 1 if n else 1
    far = 0.0
    for p in range(n):
        i, j = np.int64(np.floor(local[p, 0] * inv_t)), np.int64(np.floor(local[p, 1] * inv_t))
        qx = np.rint((local[p, 0] - i * tile_m) * inv_q)
        qy = np.rint((local[p, 1] - j * tile_m) * inv_q)
        qz = np.rint(local[p, 2] * inv_q)
        far = max(far, abs(qx), abs(qy), abs(qz))
        if far >= COUNT_LIMIT:
            return lo_i, lo_j, span_j, far
        cx, cy, cz = np.int32(qx), np.int32(qy), np.int32(qz)
        counts[p, 0], counts[p, 1], counts[p, 2] = cx, cy, cz
        bx: Any = cx // edge
        by: Any = cy // edge
        bx = 0 if bx < 0 else side - 1 if bx >= side else bx
        by = 0 if by < 0 else side - 1 if by >= side else by
        code[p] = ((i - lo_i) * span_j + (j - lo_j)) * (side * side) + by * side + bx
    return lo_i, lo_j, span_j, far
