"""The tile store's conventions: the site grid, node keys, quantisation and the persisted spec.

Tile (i, j) covers site-local x in [i T, (i + 1) T) and y in [j T, (j + 1) T), T = the site's tile
size, so the same tile covers the same ground in every scene. Inside a tile, level L keeps one point
per occupied cube of edge ``root_spacing_m / 2**L`` among the points no earlier level kept (an
additive level of detail). A node is the points of one level inside one cube of the tile's octree at
depth d = min(L, ``max_node_depth``) (edge T / 2**d, from the tile origin; COPC/EPT-like): the tile's
arrays are sorted by (level, cube), so every node is one contiguous range and levels 0..L are still
a prefix; inside a node the points are shuffled (seeded), so a node's first k points are a uniform
subsample of it and a view can read a level in part (a continuous level of detail).
Coordinates are int32 counts of ``quantum_m`` relative to the tile's float64 origin (the site origin
plus (i T, j T, 0)).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from siteline.errors import TileError

# Stored arrays per tile. Positions are stored as ``xyz_counts`` (int32 quanta from the tile origin)
# and come back from reads as ``xyz_m`` (site-local metres): the two never share a name. Stores
# written before the rename call the counts ``xyz`` (LEGACY_COUNTS); reads fall back to it.
COUNTS = "xyz_counts"
LEGACY_COUNTS = "xyz"
METRES = "xyz_m"
ATTRIBUTES = (COUNTS, "rgb", "intensity", "class", "gps_time", "return_number")
SPILL_DTYPE = np.dtype(
    [
        (COUNTS, "<i4", (3,)),
        ("rgb", "u1", (3,)),
        ("intensity", "<u2"),
        ("class", "u1"),
        ("gps_time", "<f8"),
        ("return_number", "u1"),
    ]
)

NODE_ORDERS = ("random", "input")


@dataclass(frozen=True)
class TileSpec:
    """How a scene is tiled; stored in the Zarr group's attributes and the scene's statistics.

    quantum_m: coordinate quantum (1 mm). tile_size_m: the site grid. root_spacing_m: spacing of
    level 0 (default: the largest power-of-two number of quanta within tile / 8, 4.096 m for 50 m
    tiles, so every level's cube is a whole number of quanta and nests in the level above).
    min_spacing_m: the last level takes every remaining point once the
    spacing would fall below this. max_node_depth: the deepest octree depth that splits a level into
    nodes (3: cubes of T / 8, 6.25 m for 50 m tiles; deeper levels share that grid), so a view reads
    fine levels only where it needs them. node_order: order of the points inside a node, "random"
    (seeded shuffle, so every prefix of a node is a uniform subsample of it and a view can read part
    of a level) or "input" (stores written before it: only whole nodes are read).
    chunk_points / shard_points: Zarr inner chunk and shard length. clevel: blosc-zstd level.
    """

    tile_size_m: float = 50.0
    quantum_m: float = 0.001
    root_spacing_m: float | None = None
    min_spacing_m: float = 0.02
    max_levels: int = 12
    max_node_depth: int = 3
    node_order: str = "random"
    chunk_points: int = 65_536
    shard_points: int = 1_048_576
    clevel: int = 3

    def __post_init__(self) -> None:
        if not (self.tile_size_m > 0 and self.quantum_m > 0 and self.min_spacing_m > 0):
            raise TileError("tile size, quantum and minimum spacing must be positive.")
        if self.tile_size_m / self.quantum_m > 2**30:
            raise TileError(
                f"tile size {self.tile_size_m} m at quantum {self.quantum_m} m overflows int32 counts."
            )
        if not 0 <= self.max_node_depth <= 10:
            raise TileError(f"max_node_depth {self.max_node_depth} must lie in 0..10.")
        if self.node_order not in NODE_ORDERS:
            raise TileError(f"node order {self.node_order!r} must be one of {NODE_ORDERS}.")
        if self.shard_points % self.chunk_points:
            raise TileError("shard_points must be a multiple of chunk_points.")

    @property
    def level0_spacing_m(self) -> float:
        if self.root_spacing_m is not None:
            return self.root_spacing_m
        return 2.0 ** math.floor(math.log2(self.tile_size_m / 8.0 / self.quantum_m)) * self.quantum_m

    def spacing(self, level: int) -> float:
        return self.level0_spacing_m / 2.0**level

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> TileSpec:
        """The spec a store recorded; one written before ``node_order`` existed kept input order."""
        return cls(**{"node_order": "input", **doc})


def tile_index(xy_local: np.ndarray, tile_size_m: float) -> np.ndarray:
    """(N, 2) int64 tile indices of site-local (N, 2+) float64 positions."""
    return np.floor(np.asarray(xy_local[:, :2], dtype=np.float64) / tile_size_m).astype(np.int64)


def tile_key(i: int, j: int) -> str:
    return f"t{i}_{j}"


def parse_tile_key(key: str) -> tuple[int, int]:
    i, j = key[1:].split("_")
    return int(i), int(j)


def node_key(tile: str, level: int, cell: tuple[int, int, int] | None = None) -> str:
    """``t<i>_<j>/<level>/<x>_<y>_<z>`` (the octree cube); ``t<i>_<j>/<level>`` for a whole-tile level
    (stores written before octree nodes)."""
    return f"{tile}/{level}" if cell is None else f"{tile}/{level}/{cell[0]}_{cell[1]}_{cell[2]}"


def node_cells(counts: np.ndarray, levels: np.ndarray, spec: TileSpec) -> np.ndarray:
    """(N, 3) int64 octree cube of each point's node: its position in int32 counts relative to the
    tile origin, floored by the cube edge at depth min(level, max_node_depth); x and y clamped into
    the tile (a point rounded onto the far edge stays in the last cube)."""
    n_tile = int(round(spec.tile_size_m / spec.quantum_m))
    depth = np.minimum(levels.astype(np.int64), spec.max_node_depth)
    edge = np.maximum(n_tile >> depth, 1)[:, None]
    cells = np.floor_divide(counts.astype(np.int64), edge)
    cells[:, :2] = np.clip(cells[:, :2], 0, (1 << depth)[:, None] - 1)
    return cells


def tile_origin_local(i: int, j: int, tile_size_m: float) -> np.ndarray:
    """Site-local float64 origin of tile (i, j)."""
    return np.array([i * tile_size_m, j * tile_size_m, 0.0])


def quantise(local: np.ndarray, origin_local: np.ndarray, quantum_m: float) -> np.ndarray:
    """int32 counts of ``quantum_m`` of site-local float64 points relative to ``origin_local``."""
    q = np.rint((np.asarray(local, dtype=np.float64) - origin_local) / quantum_m)
    if np.abs(q).max(initial=0) >= 2**31 - 1:
        raise TileError("a coordinate overflows the int32 tile counts; is the tile size right?")
    return q.astype(np.int32)


def dequantise(counts: np.ndarray, origin_local: np.ndarray, quantum_m: float) -> np.ndarray:
    """Site-local float64 points of int32 counts (the one place raw counts become metres)."""
    return np.asarray(origin_local, dtype=np.float64) + counts.astype(np.float64) * quantum_m


def level_count(spec: TileSpec) -> int:
    """Levels before the spacing falls below ``min_spacing_m`` (the last one takes the rest)."""
    n = int(math.floor(math.log2(spec.level0_spacing_m / spec.min_spacing_m))) + 1
    return max(1, min(spec.max_levels, n))
