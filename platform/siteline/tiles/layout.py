"""The tile store's conventions: the site grid, node keys and quantisation (the persisted spec is
:class:`siteline.records.tiling.TileSpec`).

Tile (i, j) covers site-local x in [i T, (i + 1) T) and y in [j T, (j + 1) T), T = the site's tile
size, so the same tile covers the same ground in every scene. Inside a tile, level L keeps one point
per occupied cube of edge ``root_spacing_m / 2**L`` among the points no earlier level kept (an
additive level of detail). A node is a band of levels inside one cube of the tile's octree, sized to
hold thousands of points (siteline.pointpass.nodes): the tile's arrays are sorted by (band, cube, level),
so every node is one contiguous range whose coarser levels come first; inside a level the points are
in ``TileSpec.node_order`` (by default sorted by the bit-reversed Morton code of their low bits), so that every
prefix of the level spans the node and a view can read a level in part (a continuous level of detail). The node index
is stored beside the tiles (siteline.tiles.index).
Coordinates are int32 counts of ``quantum_m`` relative to the tile's float64 origin (the site origin
plus (i T, j T, 0)).
"""

from __future__ import annotations

import numpy as np

from siteline.pointpass import ATTRIBUTES as ATTRIBUTES
from siteline.pointpass import COUNTS as COUNTS  # the name tiles store their positions under

# Stored arrays per tile. Positions are stored as ``xyz_counts`` (int32 quanta from the tile origin)
# and come back from reads as ``xyz_m`` (site-local metres): the two never share a name. Stores
# written before the rename call the counts ``xyz`` (LEGACY_COUNTS); reads fall back to it.
LEGACY_COUNTS = "xyz"
METRES = "xyz_m"


def tile_index(xy_local: np.ndarray, tile_size_m: float) -> np.ndarray:
    """(N, 2) int64 tile indices of site-local (N, 2+) float64 positions."""
    return np.floor(np.asarray(xy_local[:, :2], dtype=np.float64) / tile_size_m).astype(np.int64)


def tile_key(i: int, j: int) -> str:
    return f"t{i}_{j}"


def parse_tile_key(key: str) -> tuple[int, int]:
    i, j = key[1:].split("_")
    return int(i), int(j)


def tile_origin_local(i: int, j: int, tile_size_m: float) -> np.ndarray:
    """Site-local float64 origin of tile (i, j)."""
    return np.array([i * tile_size_m, j * tile_size_m, 0.0])
