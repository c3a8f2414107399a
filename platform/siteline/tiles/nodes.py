"""A tile's nodes: bands of levels cut into octree cubes so that every node holds thousands of points
(pure functions over one tile's arrays; the index they make is :class:`siteline.records.NodeTable`).

Levels are grouped, coarse first, into bands of at least ``spec.node_points`` points of the tile (a
short tail joins the band before it); a band is cut into the cubes of the deepest octree depth (at
most ``spec.max_node_depth``) at which its occupied cubes still hold ``spec.node_points`` on average.
A node is one band in one cube, one contiguous range of the tile's arrays: its points sorted by
level and shuffled (seeded) inside a level, so a node's first k points are its coarser levels whole
and a uniform subsample of the next. The index thus grows with points / ``node_points``, not with
levels x cubes (about 100 points a node before).

Cubes: depth d splits the tile into 2**d x 2**d columns of edge ``(T / quantum) >> max_node_depth``
quanta times 2**(max_node_depth - d), from the tile origin; z is cut with the same edge from z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from siteline.errors import TileError
from siteline.records.tiling import NodeTable, TileSpec
from siteline.tiles.sorting import sort_by_key

_LEVEL_BITS = 4
_CUBE_BITS = 30


@dataclass(frozen=True)
class TileOrder:
    """A tile's point order and nodes: ``order`` (N,) indices that sort its points into nodes, and per
    node (in array order) its band, depth, cube, start, count and points per level."""

    order: np.ndarray
    first_level: np.ndarray
    level: np.ndarray
    depth: np.ndarray
    cell: np.ndarray
    start: np.ndarray
    count: np.ndarray
    level_counts: np.ndarray


def bands(per_level: np.ndarray, target: int) -> list[tuple[int, int]]:
    """Consecutive level ranges [first, last], coarse first, each holding at least ``target`` of
    ``per_level``'s points where there are that many (a short tail joins the band before it)."""
    out: list[tuple[int, int]] = []
    level, last = 0, len(per_level) - 1
    while level <= last:
        first, total = level, int(per_level[level])
        while total < target and level < last:
            level += 1
            total += int(per_level[level])
        out.append((first, level))
        level += 1
    if len(out) > 1 and int(per_level[out[-1][0] : out[-1][1] + 1].sum()) < target:
        out[-2:] = [(out[-2][0], out[-1][1])]
    return out


def fine_cubes(counts: np.ndarray, spec: TileSpec) -> np.ndarray:
    """(N, 3) int64 cube of each point at depth ``spec.max_node_depth``: int32 counts from the tile
    origin floored by the cube edge, x and y clamped into the tile (a point rounded onto the far edge
    stays in the last cube)."""
    depth = spec.max_node_depth
    edge = max(int(round(spec.tile_size_m / spec.quantum_m)) >> depth, 1)
    cubes = np.floor_divide(counts, np.int32(edge)).astype(np.int64)
    np.clip(cubes[:, :2], 0, (1 << depth) - 1, out=cubes[:, :2])
    return cubes


def _depths(cubes: np.ndarray, band_of_point: np.ndarray, totals: np.ndarray, spec: TileSpec) -> np.ndarray:
    """Per band, the deepest depth whose occupied cubes average ``spec.node_points`` (0 when none)."""
    top = spec.max_node_depth
    nb = len(totals)
    zmin = int(cubes[:, 2].min())
    ids = (cubes[:, 2] - zmin) << (2 * top) | cubes[:, 1] << top | cubes[:, 0]
    m = int(ids.max()) + 1
    if nb * m > 2**26:  # a cloud thousands of cubes tall: judge the depth by columns
        ids = cubes[:, 1] << top | cubes[:, 0]
        m = 1 << (2 * top)
    occupied = np.bincount(band_of_point * m + ids, minlength=nb * m).reshape(nb, m) > 0
    out = np.zeros(nb, np.int64)
    for b in range(nb):
        fine = np.flatnonzero(occupied[b])
        x, y, z = fine & ((1 << top) - 1), (fine >> top) & ((1 << top) - 1), fine >> (2 * top)
        for d in range(top, 0, -1):
            s = top - d
            held = len(np.unique((z >> s) << (2 * d) | (y >> s) << d | (x >> s)))
            if totals[b] >= spec.node_points * held:
                out[b] = d
                break
    return out


def order_tile(counts: np.ndarray, levels: np.ndarray, spec: TileSpec, n_levels: int, seed: int) -> TileOrder:
    """The node order of one tile's points. counts: (N, 3) int32 quanta from the tile origin; levels:
    (N,) uint8 (siteline.tiles.lod); n_levels: the spec's level count. One sort by (band, cube,
    level), ties broken by a seeded permutation (``node_order="input"``: by input order)."""
    n = len(levels)
    per_level = np.bincount(levels, minlength=n_levels)
    spans = bands(per_level, spec.node_points)
    band_of_level = np.zeros(max(n_levels, int(levels.max(initial=0)) + 1), np.int64)
    for b, (f, last) in enumerate(spans):
        band_of_level[f : last + 1] = b
    band = band_of_level[levels]
    cubes = fine_cubes(counts, spec)
    totals = np.array([per_level[f : last + 1].sum() for f, last in spans])
    depth_of_band = _depths(cubes, band, totals, spec)
    shift = spec.max_node_depth - depth_of_band[band]
    d = depth_of_band[band]
    z = cubes[:, 2] >> shift
    z0 = z.min(initial=0)
    cube = (z - z0) << (2 * d) | (cubes[:, 1] >> shift) << d | (cubes[:, 0] >> shift)
    if n and int(cube.max()) >= 1 << _CUBE_BITS:
        raise TileError("a tile's points span too many cubes in z to index: is the z unit right?")
    if spec.node_order == "random":  # a seeded shuffle inside each level of a node
        point_of = np.random.default_rng(seed).permutation(n)
        tie = np.empty(n, np.int64)
        tie[point_of] = np.arange(n)
    else:  # input order
        point_of, tie = None, np.arange(n)
    cube_bits = max(int(cube.max(initial=0)).bit_length(), 1)
    key = (band << cube_bits | cube) << _LEVEL_BITS | levels.astype(np.int64)
    key_sorted, tie_sorted = sort_by_key(key, tie)
    order = point_of[tie_sorted] if point_of is not None else tie_sorted
    band_cube = key_sorted >> _LEVEL_BITS
    new = np.ones(n, dtype=bool)
    new[1:] = band_cube[1:] != band_cube[:-1]
    start = np.flatnonzero(new)
    count = np.diff(np.r_[start, n])
    node = np.cumsum(new) - 1
    width = len(band_of_level)
    lc = np.bincount(
        node * width + (key_sorted & ((1 << _LEVEL_BITS) - 1)), minlength=len(start) * width
    ).reshape(len(start), width)
    nb = band_cube[start] >> cube_bits
    nd = depth_of_band[nb]
    nc = band_cube[start] & ((1 << cube_bits) - 1)
    cell = np.stack([nc & ((1 << nd) - 1), (nc >> nd) & ((1 << nd) - 1), (nc >> (2 * nd)) + z0], axis=1)
    span = np.array(spans, np.uint8).reshape(-1, 2)[nb]
    return TileOrder(
        order, span[:, 0], span[:, 1], nd.astype(np.int8), cell.astype(np.int32), start, count, lc
    )


def tile_table(tile: str, ordered: TileOrder, local_sorted: np.ndarray) -> NodeTable:
    """The node rows of one tile from its order and its points' site-local float64 positions (sorted)."""
    lo = np.minimum.reduceat(local_sorted, ordered.start, axis=0)
    hi = np.maximum.reduceat(local_sorted, ordered.start, axis=0)
    return NodeTable(
        (tile,),
        tile=np.zeros(len(ordered.start), np.int32),
        first_level=ordered.first_level,
        level=ordered.level,
        depth=ordered.depth,
        cell=ordered.cell,
        start=ordered.start.astype(np.int64),
        count=ordered.count.astype(np.int64),
        lo=lo,
        hi=hi,
        level_counts=ordered.level_counts.astype(np.int64),
    )
