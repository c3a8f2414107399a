"""The engine's record schema and the bit layout of every key it packs: one place to read them.

A point travels from a LAS chunk to a tile as one :data:`RECORD` (the partition's run files hold
them; the tile store keeps one array per field, siteline.tiles.codecs). Keys are int64:

- a **cell** (:func:`cell_ids`): ``((i + 2**20) << 21 | (j + 2**20)) << 16 | block`` — the site-grid
  tile (i, j) and the block inside it (row-major, at most 256 a side), ordered by tile then block;
- a **cube count** key (tiles' node plan): ``level << 48 | (cube z + 2**20) << 2d | cube y << d | cube x``
  at depth d;
- a **group** key: ``(band << cube bits | cube) << 4 | level``;
- a **voxel** key (:func:`voxel_key`, the level-of-detail fallback): ``(x + 2**20) | (y + 2**20) << 21 |
  z << 42`` of a point's voxel;
- a **node-order** key: the Morton code of the low :data:`ORDER_BITS` bits of a point's counts, read
  from the lowest bit up (x, y, z).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from siteline.errors import TileError

# the stored arrays of a tile, as one record: int32 quanta from the tile origin, then the attributes
COUNTS = "xyz_counts"
RECORD = np.dtype(
    [
        (COUNTS, "<i4", (3,)),
        ("rgb", "u1", (3,)),
        ("intensity", "<u2"),
        ("class", "u1"),
        ("gps_time", "<f8"),
        ("return_number", "u1"),
    ]
)
ATTRIBUTES: tuple[str, ...] = RECORD.names or ()

# cell keys
TILE_OFFSET = 1 << 20  # added to a tile index so it packs unsigned
TILE_BITS = 21  # bits of each tile index
BLOCK_BITS = 16  # bits of a block inside its tile: at most 256 blocks a side

# cube-count and group keys of a tile's node plan
LEVEL_SHIFT = 48  # a level's place in a cube-count key
Z_OFFSET = 1 << 20  # added to a cube's z in a cube-count key
LEVEL_BITS = 4  # a level's bits at the bottom of a group key

# node-order keys
ORDER_BITS = 4  # the low bits of each count a node-order key holds

# voxel keys: 21 bits for x and y each, offset so they pack unsigned
VOXEL_OFFSET = 1 << 20
VOXEL_BITS = 21

# the largest count an int32 tile count holds (a quantised coordinate at or past it overflows)
COUNT_LIMIT = 2**31 - 1


def cell_ids(ij: np.ndarray, block: np.ndarray) -> np.ndarray:
    """(N,) int64 ids of (site-grid tile (N, 2), block in the tile (N,)), ordered by tile then block."""
    return ((ij[:, 0] + TILE_OFFSET) << TILE_BITS | (ij[:, 1] + TILE_OFFSET)) << BLOCK_BITS | block


def tile_of(cell: int) -> tuple[int, int]:
    """The (i, j) of a cell id."""
    tile_id = cell >> BLOCK_BITS
    return (tile_id >> TILE_BITS) - TILE_OFFSET, (tile_id & ((1 << TILE_BITS) - 1)) - TILE_OFFSET


def block_of(cell: int) -> int:
    """The block (inside its tile) of a cell id."""
    return cell & ((1 << BLOCK_BITS) - 1)


def pack_cube(x: np.ndarray, y: np.ndarray, z: np.ndarray, d: int | np.ndarray) -> np.ndarray:
    """Cubes (x, y, z) at octree depth ``d`` packed z, y, x row-major: ``z << 2d | y << d | x``."""
    return z << (2 * d) | y << d | x


def unpack_cube(cube: np.ndarray, d: int | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (x, y, z) of cubes packed at depth ``d`` by :func:`pack_cube`."""
    mask = (1 << d) - 1
    return cube & mask, (cube >> d) & mask, cube >> (2 * d)


def cube_count_key(level: Any, x: Any, y: Any, z: Any, d: Any) -> Any:
    """The cube-count key of a finest cube (x, y, z) at depth ``d`` (z may be negative) and a level:
    ``level << 48 | (z + 2**20) << 2d | y << d | x`` (the cube packed as :func:`pack_cube` does; written
    out, as the kernels compile this function alone)."""
    return level << LEVEL_SHIFT | (z + Z_OFFSET) << (2 * d) | y << d | x


def split_cube_count_key(key: np.ndarray, top: int) -> tuple[np.ndarray, np.ndarray]:
    """(level (M,), finest cube (M, 3) x, y, z) of cube-count keys at depth ``top``."""
    x, y, z = unpack_cube(key & ((1 << LEVEL_SHIFT) - 1), top)
    return key >> LEVEL_SHIFT, np.c_[x, y, z - Z_OFFSET]


def group_key(band: np.ndarray, cube: np.ndarray, level: np.ndarray, cube_bits: int) -> np.ndarray:
    """Packed (band, cube, level) group keys: ``(band << cube_bits | cube) << LEVEL_BITS | level``."""
    return (band << cube_bits | cube) << LEVEL_BITS | level


def split_group_key(key: np.ndarray, cube_bits: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(band, cube, level) of group keys (:func:`group_key`)."""
    band_cube = key >> LEVEL_BITS
    return band_cube >> cube_bits, band_cube & ((1 << cube_bits) - 1), key & ((1 << LEVEL_BITS) - 1)


def group_node(key: np.ndarray) -> np.ndarray:
    """The (band, cube) part of group keys: keys that share it are one node."""
    return key >> LEVEL_BITS


def voxel_key(x: Any, y: Any, z: Any) -> Any:
    """The voxel key of integer voxel coordinates (x and y within +-2**20, z from 0):
    ``(x + 2**20) | (y + 2**20) << 21 | z << 42``."""
    return (x + VOXEL_OFFSET) | ((y + VOXEL_OFFSET) << VOXEL_BITS) | (z << (2 * VOXEL_BITS))


def order_key(x: Any, y: Any, z: Any) -> Any:
    """The node-order key of a point (int64 counts x, y, z): the Morton code of their
    :data:`ORDER_BITS` low bits read from the lowest bit up, bit 0 of x most significant, then bit 0 of
    y, bit 0 of z, bit 1 of x, ... (12 bits)."""
    k = np.int64(0)
    for b in range(ORDER_BITS):
        k = (k << 3) | ((x >> b) & 1) << 2 | ((y >> b) & 1) << 1 | ((z >> b) & 1)
    return k


def quantise(local: np.ndarray, origin_local: np.ndarray, quantum_m: float) -> np.ndarray:
    """int32 counts of ``quantum_m`` of site-local float64 points relative to ``origin_local``."""
    q = np.rint((np.asarray(local, dtype=np.float64) - origin_local) / quantum_m)
    if np.abs(q).max(initial=0) >= COUNT_LIMIT:
        raise TileError("a coordinate overflows the int32 tile counts; is the tile size right?")
    return q.astype(np.int32)


def dequantise(counts: np.ndarray, origin_local: np.ndarray, quantum_m: float) -> np.ndarray:
    """Site-local float64 points of int32 counts (the one place raw counts become metres)."""
    return np.asarray(origin_local, dtype=np.float64) + counts.astype(np.float64) * quantum_m
