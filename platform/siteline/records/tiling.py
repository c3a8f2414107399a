"""A scene's tiling as records: the persisted spec, the node index, what tiling recorded, and what a
reader needs to open the store (DESIGN.md §7)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from typing import TYPE_CHECKING

import numpy as np

from siteline.errors import TileError
from siteline.records.enums import NODE_ORDERS, NodeOrder
from siteline.records.specs import parse_spec
from siteline.schema import JSON, json_float, json_int, json_object, json_str

if TYPE_CHECKING:
    from siteline.site.spec import SiteSpec


@dataclass(frozen=True)
class TileSpec:
    """How a scene is tiled; stored in the Zarr group's attributes and the scene's statistics.

    quantum_m: coordinate quantum (1 mm). tile_size_m: the site grid. root_spacing_m: spacing of
    level 0 (default: the largest power-of-two number of quanta within tile / 8, 4.096 m for 50 m
    tiles, so every level's cube is a whole number of quanta and nests in the level above).
    min_spacing_m: the last level takes every remaining point once the
    spacing would fall below this. node_points: the points a node holds at least where the tile has
    them (levels are banded and bands cut into cubes to reach it, siteline.pointpass.nodes): the index
    grows with points / node_points; smaller nodes cull views more finely at the cost of more rows.
    max_node_depth: the deepest octree depth that splits a band into nodes (6: cubes of T / 64,
    0.78 m for 50 m tiles; a band takes the deepest depth whose cubes still average node_points, so
    nodes stay near node_points up to tens of thousands of points/m2), so a view reads fine levels
    only where it needs them. node_order: order of the points inside each level of a node, so
    that every prefix of it is spread over the whole node and a view can read part of a level:
    "reversed-morton" (sorted by the Morton code of the 4 low bits of their counts read from the
    lowest bit up, ties in input order: a position's low bits are spread evenly over the node, and
    sorted they compress, about 1 byte a point less than "random"), "random" (a seeded shuffle), or
    "input" (stores written before either: only whole levels are read).
    chunk_points / shard_points: Zarr inner chunk and shard length. clevel: blosc-zstd level.
    """

    tile_size_m: float = 50.0
    quantum_m: float = 0.001
    root_spacing_m: float | None = None
    min_spacing_m: float = 0.02
    max_levels: int = 12
    max_node_depth: int = 6
    node_points: int = 4096
    node_order: NodeOrder = "reversed-morton"
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
        if self.node_points < 1:
            raise TileError(f"node_points {self.node_points} must be at least 1.")
        if self.node_order not in NODE_ORDERS:
            raise TileError(f"node order {self.node_order!r} must be one of {NODE_ORDERS}.")
        if self.shard_points % self.chunk_points:
            raise TileError("shard_points must be a multiple of chunk_points.")

    @classmethod
    def for_site(cls, site: SiteSpec) -> TileSpec:
        """The default spec of a site: its tile grid, every other field at its default (what ingest
        partitions for and the tile stage writes unless told otherwise)."""
        return cls(tile_size_m=site.tile_size_m)

    @property
    def level0_spacing_m(self) -> float:
        if self.root_spacing_m is not None:
            return self.root_spacing_m
        return 2.0 ** math.floor(math.log2(self.tile_size_m / 8.0 / self.quantum_m)) * self.quantum_m

    @property
    def level_count(self) -> int:
        """Levels before the spacing falls below ``min_spacing_m`` (the last one takes the rest)."""
        n = int(math.floor(math.log2(self.level0_spacing_m / self.min_spacing_m))) + 1
        return max(1, min(self.max_levels, n))

    @property
    def tile_quanta(self) -> int:
        """The tile's edge in quanta."""
        return int(round(self.tile_size_m / self.quantum_m))

    @property
    def partial_levels(self) -> bool:
        """Whether every prefix of a node's level is spread over the node (a view may read part)."""
        return self.node_order != "input"

    def spacing(self, level: int) -> float:
        return self.level0_spacing_m / 2.0**level

    def to_dict(self) -> dict[str, JSON]:
        return asdict(self)

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> TileSpec:
        """The spec a store recorded; one written before ``node_order`` existed kept input order.
        TileError names an unknown key or a wrongly typed value."""
        return parse_spec(cls, {"node_order": "input", **doc}, "tile spec", TileError)


# the columns of a node index, in storage order: name -> (dtype, values per row; 0: one per level)
NODE_COLUMNS: dict[str, tuple[str, int]] = {
    "tile": ("int32", 1),
    "first_level": ("uint8", 1),
    "level": ("uint8", 1),
    "depth": ("int8", 1),
    "cell": ("int32", 3),
    "start": ("int64", 1),
    "count": ("int64", 1),
    "lo": ("float64", 3),
    "hi": ("float64", 3),
    "level_counts": ("int64", 0),
}


@dataclass(frozen=True, eq=False)
class NodeTable:
    """A scene's node index, one row per node, as columns (siteline.pointpass.nodes).

    A node is the levels ``first_level..level`` (a band) inside one octree cube ``cell`` at ``depth``
    of tile ``tiles[tile]`` (depth -1: the whole tile), one contiguous range ``start``/``count`` of the
    tile's arrays; ``level_counts[:, L]``: its points at level L, stored level by level. ``lo``/``hi``:
    bounds of its points, site-local metres."""

    tiles: tuple[str, ...]
    tile: np.ndarray
    first_level: np.ndarray
    level: np.ndarray
    depth: np.ndarray
    cell: np.ndarray
    start: np.ndarray
    count: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    level_counts: np.ndarray

    def __len__(self) -> int:
        return len(self.start)

    @property
    def points(self) -> int:
        return int(self.count.sum())

    @property
    def levels(self) -> int:
        """Levels that hold points (the deepest + 1)."""
        held = np.flatnonzero(self.level_counts.sum(axis=0))
        return int(held[-1]) + 1 if len(held) else 0

    def columns(self) -> dict[str, np.ndarray]:
        """The columns by name (:data:`NODE_COLUMNS`), for storage."""
        return {name: getattr(self, name) for name in NODE_COLUMNS}

    @classmethod
    def from_columns(cls, tiles: Sequence[str], columns: Mapping[str, np.ndarray | None]) -> NodeTable:
        """The table of stored columns; :class:`TileError` when one is missing or they disagree."""
        missing = [c for c in NODE_COLUMNS if c not in columns]
        if missing:
            raise TileError(f"the node index lacks columns {missing}: the store is damaged.")
        cols = {c: np.asarray(columns[c], dtype=NODE_COLUMNS[c][0]) for c in NODE_COLUMNS}
        if len({len(v) for v in cols.values()}) != 1:
            raise TileError("the node index's columns differ in length: the store is damaged.")
        if len(cols["tile"]) and (int(cols["tile"].max()) >= len(tiles) or int(cols["tile"].min()) < 0):
            raise TileError("the node index names a tile the store does not list: the store is damaged.")
        if not np.array_equal(cols["level_counts"].sum(axis=1), cols["count"]):
            raise TileError(
                "the node index's level counts do not add up to its counts: the store is damaged."
            )
        return cls(tuple(str(t) for t in tiles), **cols)

    @classmethod
    def empty(cls, levels: int = 1) -> NodeTable:
        cols = {c: np.zeros((0, w) if w > 1 else 0, dtype=d) for c, (d, w) in NODE_COLUMNS.items()}
        cols["level_counts"] = np.zeros((0, levels), np.int64)
        return cls((), **cols)

    @classmethod
    def concat(cls, tables: Sequence[NodeTable]) -> NodeTable:
        """One table of several (their tiles listed in order, tile ids renumbered)."""
        if not tables:
            return cls.empty()
        tiles: list[str] = []
        parts: dict[str, list[np.ndarray]] = {c: [] for c in NODE_COLUMNS}
        width = max(t.level_counts.shape[1] for t in tables)
        for t in tables:
            for c in NODE_COLUMNS:
                v = getattr(t, c)
                if c == "tile":
                    v = v + np.int32(len(tiles))
                elif c == "level_counts":
                    v = np.pad(v, ((0, 0), (0, width - v.shape[1])))
                parts[c].append(v)
            tiles += t.tiles
        return cls(tuple(tiles), **{c: np.concatenate(v) for c, v in parts.items()})

    def rows(self, keep: np.ndarray) -> NodeTable:
        """The rows ``keep`` (a mask or indices), the tile list unchanged."""
        return replace(self, **{c: getattr(self, c)[keep] for c in NODE_COLUMNS})

    def key(self, row: int) -> str:
        """A readable name of node ``row``: ``t<i>_<j>/<first>-<last>[/<x>_<y>_<z>]``."""
        tile, first, last = self.tiles[int(self.tile[row])], int(self.first_level[row]), int(self.level[row])
        levels = f"{first}" if first == last else f"{first}-{last}"
        if self.depth[row] < 0:
            return f"{tile}/{levels}"
        x, y, z = (int(v) for v in self.cell[row])
        return f"{tile}/{levels}/{x}_{y}_{z}"

    @classmethod
    def from_legacy(cls, docs: Sequence[Mapping[str, JSON]], spec: TileSpec) -> NodeTable:
        """The table of the node list a store written before node tables kept as JSON in its
        attributes (one level per node; ``cell`` null: a whole-tile level)."""
        if not docs:
            return cls.empty(spec.max_levels)
        try:
            tiles = sorted({str(d["tile"]) for d in docs})
            ids = {t: k for k, t in enumerate(tiles)}
            level = np.array([json_int(d["level"], "level") for d in docs], np.uint8)
            count = np.array([json_int(d["count"], "count") for d in docs], np.int64)
            cells = [d.get("cell") for d in docs]
            lc = np.zeros((len(docs), max(spec.max_levels, int(level.max()) + 1)), np.int64)
            lc[np.arange(len(docs)), level] = count
            return cls(
                tuple(tiles),
                tile=np.array([ids[str(d["tile"])] for d in docs], np.int32),
                first_level=level.copy(),
                level=level,
                depth=np.array(
                    [
                        -1 if c is None else min(int(lv), spec.max_node_depth)
                        for c, lv in zip(cells, level, strict=True)
                    ],
                    np.int8,
                ),
                cell=np.array([c if c is not None else (0, 0, 0) for c in cells], np.int32).reshape(-1, 3),
                start=np.array([json_int(d["start"], "start") for d in docs], np.int64),
                count=count,
                lo=np.array([d["bounds_min"] for d in docs], np.float64).reshape(-1, 3),
                hi=np.array([d["bounds_max"] for d in docs], np.float64).reshape(-1, 3),
                level_counts=lc,
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise TileError(f"the store's node list is malformed ({exc!r}): tile the scene again.") from exc


@dataclass(frozen=True)
class SceneTiling:
    """What tiling a scene recorded (``scene.statistics["tiles"]``): the store's address, spec and
    checksum (a label-set store follows the order it implies), its generation (0 until the scene is
    tiled again; part of its pairs' output keys), and counts: points, tiles, levels, bytes on disk,
    seconds spent, node index rows, the bytes of the LAS/LAZ file it was tiled from (0: not
    recorded), to compare bytes per point with, and the version of the site (its taxonomy and fence)
    the classes were mapped under."""

    uri: str
    spec: TileSpec
    checksum: str
    generation: int
    points: int
    tiles: int
    levels: int
    bytes: int
    seconds: float
    nodes: int = 0
    source_bytes: int = 0
    site_version: int = 1

    @property
    def bytes_per_point(self) -> float:
        return self.bytes / max(self.points, 1)

    @property
    def source_bytes_per_point(self) -> float:
        return self.source_bytes / max(self.points, 1)

    def to_dict(self) -> dict[str, JSON]:
        doc = {f.name: getattr(self, f.name) for f in fields(self)}
        return doc | {
            "spec": self.spec.to_dict(),
            "bytes_per_point": self.bytes_per_point,
            "source_bytes_per_point": self.source_bytes_per_point,
        }

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> SceneTiling:
        return cls(
            uri=json_str(doc["uri"], "uri"),
            spec=TileSpec.from_dict(json_object(doc["spec"], "spec")),
            checksum=json_str(doc["checksum"], "checksum"),
            generation=json_int(doc.get("generation", 0), "generation"),
            points=json_int(doc["points"], "points"),
            tiles=json_int(doc["tiles"], "tiles"),
            levels=json_int(doc["levels"], "levels"),
            bytes=json_int(doc["bytes"], "bytes"),
            seconds=json_float(doc.get("seconds", 0.0), "seconds"),
            nodes=json_int(doc.get("nodes", 0), "nodes"),
            source_bytes=json_int(doc.get("source_bytes", 0), "source_bytes"),
            site_version=json_int(doc.get("site_version", 1), "site_version"),
        )


@dataclass(frozen=True)
class TileSource:
    """What a reader needs to open a scene's tile store: its address, spec and checksum (what a
    label-set store must have been made for; the node index is read from the store), and the stores of attributes read beside the
    tile arrays (``class`` of a label-set version, ``change`` of a pair's labels), each laid out as
    ``tiles/<tile>/<name>``."""

    uri: str
    spec: TileSpec
    checksum: str | None = None
    attributes: Mapping[str, str] = field(default_factory=dict)
