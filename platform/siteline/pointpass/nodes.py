"""A tile's nodes: bands of levels cut into octree cubes so that every node holds thousands of points
(pure functions over one tile's arrays; the index they make is :class:`siteline.records.tiling.NodeTable`).

A tile's node plan is made from its points counted per (level, finest node cube) (:func:`cube_counts`,
which adds up over batches of points), and each point is then placed by its group (band, cube,
level) in the group's slots (:meth:`NodePlan.place`: in input order, or a seeded permutation for
``node_order="random"``): so a tile too big for memory is placed batch after batch, and gets the
same arrays whatever its batches. With ``node_order="reversed-morton"`` each group's points are then
sorted by their order key (:meth:`NodePlan.node_order`, over whole groups once all are placed).

Levels are grouped, coarse first, into bands of at least ``spec.node_points`` points of the tile (a
short tail joins the band before it); a band is cut into the cubes of the deepest octree depth (at
most ``spec.max_node_depth``) at which its occupied cubes still hold ``spec.node_points`` on average.
A node is one band in one cube, one contiguous range of the tile's arrays: its points sorted by
level and in node order inside a level, so a node's first k points are its coarser levels whole
and a subsample of the next spread over the node. The index thus grows with points /
``node_points``, not with levels x cubes (about 100 points a node before).

Cubes: depth d splits the tile into 2**d x 2**d columns of edge ``(T / quantum) >> max_node_depth``
quanta times 2**(max_node_depth - d), from the tile origin; z is cut with the same edge from z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from siteline.errors import TileError
from siteline.pointpass.kernels import nodes as node_kernels
from siteline.pointpass.schema import (
    group_key,
    group_node,
    pack_cube,
    split_cube_count_key,
    split_group_key,
    unpack_cube,
)
from siteline.records.tiling import NodeTable, TileSpec

_CUBE_BITS = 30


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


def _fine_edge(spec: TileSpec) -> int:
    """The edge in quanta of the cubes at depth ``spec.max_node_depth``: depth d splits the tile into
    2**d x 2**d columns from its origin, z cut with the same edge from z = 0 (x and y clamped into
    the tile, so a point rounded onto its far edge stays in the last cube)."""
    return max(spec.tile_quanta >> spec.max_node_depth, 1)


def cube_counts(counts: np.ndarray, levels: np.ndarray, spec: TileSpec) -> np.ndarray:
    """(M, 2) int64 rows of (level and finest cube, points) of one batch of a tile's points, sorted:
    counts (N, 3) int32 quanta from the tile origin, levels (N,) uint8. :func:`add_cube_counts` adds
    the rows of several batches."""
    rows = node_kernels.cube_rows(np.ascontiguousarray(counts), levels, _fine_edge(spec), spec.max_node_depth)
    if len(counts) and not len(rows):
        raise TileError("a tile's points span too many cubes in z to index: is the z unit right?")
    return rows


def add_cube_counts(parts: list[np.ndarray]) -> np.ndarray:
    """The rows of :func:`cube_counts` of several batches of one tile, added up."""
    rows = np.concatenate(parts) if parts else np.zeros((0, 2), np.int64)
    order = np.argsort(rows[:, 0], kind="stable")
    return _runs(rows[order, 0], rows[order, 1])


def _runs(sorted_key: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """(M, 2) rows of each distinct key of ``sorted_key`` and its summed ``weight``."""
    if not len(sorted_key):
        return np.zeros((0, 2), np.int64)
    start = np.r_[0, np.flatnonzero(sorted_key[1:] != sorted_key[:-1]) + 1]
    return np.c_[sorted_key[start], np.add.reduceat(weight, start)]


def _depths(band: np.ndarray, fine: np.ndarray, totals: np.ndarray, spec: TileSpec) -> np.ndarray:
    """Per band, the deepest depth whose occupied cubes average ``spec.node_points`` (0 when none).
    band, fine: (M,) each occupied (band, finest cube (x, y, z) packed as in :func:`cube_counts`)."""
    top = spec.max_node_depth
    out = np.zeros(len(totals), np.int64)
    x, y, z = unpack_cube(fine, top)
    for b in range(len(totals)):
        mine = band == b
        for d in range(top, 0, -1):
            s = top - d
            held = len(np.unique(pack_cube(x[mine] >> s, y[mine] >> s, z[mine] >> s, d)))
            if totals[b] >= spec.node_points * held:
                out[b] = d
                break
    return out


@dataclass(frozen=True)
class NodePlan:
    """Where a tile's points go: its groups (one band of one cube at one level) in array order, by
    ``key`` (band, cube, level packed), each group's ``start`` and ``count`` in the tile's arrays; and
    the nodes (a band in a cube: its groups) with their band, depth, cube, start, count and points
    per level. ``order``: the spec's node order; ``seed`` seeds each group's slot permutation when
    it is "random"."""

    key: np.ndarray
    start: np.ndarray
    count: np.ndarray
    band_of_level: np.ndarray
    depth_of_band: np.ndarray
    z0: int
    cube_bits: int
    seed: int
    order: str
    first_level: np.ndarray
    level: np.ndarray
    depth: np.ndarray
    cell: np.ndarray
    node_start: np.ndarray
    node_count: np.ndarray
    level_counts: np.ndarray

    @property
    def points(self) -> int:
        return int(self.count.sum())

    def place(self, counts: np.ndarray, levels: np.ndarray, spec: TileSpec, seen: np.ndarray) -> np.ndarray:
        """(N,) array position of each of a batch of points (counts (N, 3) int32 quanta from the tile
        origin, levels (N,) uint8, in the tile's order): group g's points take its slots in a seeded
        permutation, batch after batch (``seen``: per group, the points earlier batches placed;
        updated)."""
        grid = (_fine_edge(spec), spec.max_node_depth, self.z0, self.cube_bits)
        group = node_kernels.group_points(
            np.ascontiguousarray(counts), levels, grid, self.band_of_level, self.depth_of_band, self.key
        )
        where = group if len(group) and group[0] < 0 else node_kernels.slot_points(
            group, self.start, self.count, seen, self.seed, self.order == "random"
        )  # fmt: skip
        if len(where) and where[0] < 0:
            raise TileError("a tile's points changed between its node plan and their placement.")
        return where

    @cached_property
    def bounds(self) -> np.ndarray:
        """(G + 1,) the first row of each group in the tile's arrays, then the row past the last."""
        return np.r_[self.start, self.points]

    def groups_around(self, a: int, b: int) -> tuple[int, int]:
        """Rows [lo, hi) of the tile's arrays: the whole groups that hold rows [a, b)."""
        bounds = self.bounds
        return int(bounds[np.searchsorted(bounds, a, "right") - 1]), int(bounds[np.searchsorted(bounds, b)])

    def node_order(self, counts: np.ndarray, lo: int) -> np.ndarray:
        """The order that puts placed rows [lo, lo + len(counts)) (whole groups; counts (M, 3) int32) in
        node order: each group sorted by :func:`siteline.pointpass.schema.order_key` of its points,
        ties in input order, for "reversed-morton"; as placed otherwise."""
        if self.order != "reversed-morton":
            return np.arange(len(counts))
        bounds = self.bounds
        inner = bounds[(bounds >= lo) & (bounds <= lo + len(counts))] - lo
        if len(counts) and (inner[0] != 0 or inner[-1] != len(counts)):
            raise TileError("a tile's rows to order do not cover whole groups of its node plan.")
        return node_kernels.order_in_groups(counts, inner)

    def table(self, tile: str, lo: np.ndarray, hi: np.ndarray) -> NodeTable:
        """The node rows of the tile with its nodes' bounds (site-local metres)."""
        return NodeTable(
            (tile,),
            tile=np.zeros(len(self.node_start), np.int32),
            first_level=self.first_level,
            level=self.level,
            depth=self.depth,
            cell=self.cell,
            start=self.node_start,
            count=self.node_count,
            lo=lo,
            hi=hi,
            level_counts=self.level_counts,
        )


def _cube(d: np.ndarray, cubes: np.ndarray, spec: TileSpec, z0: int) -> np.ndarray:
    """Each finest cube's cube at depth ``d``: z, y, x row-major at that depth, z counted from z0."""
    shift = spec.max_node_depth - d
    return pack_cube(cubes[:, 0] >> shift, cubes[:, 1] >> shift, (cubes[:, 2] >> shift) - z0, d)


def _group_key(
    band: np.ndarray,
    d: np.ndarray,
    cubes: np.ndarray,
    levels: np.ndarray,
    spec: TileSpec,
    z0: int,
    cube_bits: int,
) -> np.ndarray:
    """Packed (band, cube at depth ``d``, level): the order of a tile's arrays."""
    return group_key(band, _cube(d, cubes, spec, z0), levels.astype(np.int64), cube_bits)


def plan_nodes(rows: np.ndarray, spec: TileSpec, n_levels: int, seed: int) -> NodePlan:
    """The node plan of a tile from its (level, finest cube) point counts (:func:`cube_counts`)."""
    top = spec.max_node_depth
    level, cubes = split_cube_count_key(rows[:, 0], top)
    per_level = np.bincount(level, weights=rows[:, 1], minlength=n_levels).astype(np.int64)
    spans = bands(per_level, spec.node_points)
    band_of_level = np.zeros(max(n_levels, len(per_level)), np.int64)
    for b, (f, last) in enumerate(spans):
        band_of_level[f : last + 1] = b
    band = band_of_level[level]
    totals = np.array([per_level[f : last + 1].sum() for f, last in spans])
    packed = pack_cube(cubes[:, 0], cubes[:, 1], cubes[:, 2] - cubes[:, 2].min(initial=0), top)
    depth_of_band = _depths(band, packed, totals, spec)
    d = depth_of_band[band]
    z0 = int((cubes[:, 2] >> (top - d)).min(initial=0))
    cube_max = int(_cube(d, cubes, spec, z0).max(initial=0))
    if cube_max >= 1 << _CUBE_BITS:
        raise TileError("a tile's points span too many cubes in z to index: is the z unit right?")
    cube_bits = max(cube_max.bit_length(), 1)
    key = _group_key(band, d, cubes, level, spec, z0, cube_bits)
    order = np.argsort(key, kind="stable")
    groups = _runs(key[order], rows[order, 1])
    return _with_nodes(groups, spans, depth_of_band, band_of_level, z0, cube_bits, seed, spec)


def _with_nodes(
    groups: np.ndarray, spans: list[tuple[int, int]], depth_of_band: np.ndarray, band_of_level: np.ndarray,
    z0: int, cube_bits: int, seed: int, spec: TileSpec,
) -> NodePlan:  # fmt: skip
    """The plan of the groups (key, count) in array order, with their nodes (a count per level of
    ``band_of_level``)."""
    key, count = groups[:, 0], groups[:, 1]
    start = np.r_[0, np.cumsum(count)[:-1]].astype(np.int64) if len(count) else np.zeros(0, np.int64)
    band_cube = group_node(key)
    head = (
        np.r_[0, np.flatnonzero(band_cube[1:] != band_cube[:-1]) + 1] if len(key) else np.zeros(0, np.int64)
    )
    new = np.zeros(len(key), bool)
    new[head] = True
    node = np.cumsum(new) - 1
    lc = np.zeros((len(head), len(band_of_level)), np.int64)
    np.add.at(lc, (node, split_group_key(key, cube_bits)[2]), count)
    nb, nc, _ = split_group_key(key[head], cube_bits)
    nd = depth_of_band[nb]
    cx, cy, cz = unpack_cube(nc, nd)
    cell = np.stack([cx, cy, cz + z0], axis=1)
    span = np.array(spans, np.uint8).reshape(-1, 2)[nb]
    return NodePlan(
        key, start, count, band_of_level, depth_of_band, z0, cube_bits, seed, spec.node_order,
        span[:, 0], span[:, 1], nd.astype(np.int8), cell.astype(np.int32).reshape(-1, 3), start[head],
        lc.sum(axis=1), lc,
    )  # fmt: skip
