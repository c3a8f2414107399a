"""A scene's tiling as records: the persisted spec, the node index, what tiling recorded, and what a
reader needs to open the store (DESIGN.md §7)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from siteline.errors import TileError
from siteline.records.enums import NODE_ORDERS, NodeOrder


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
    node_order: NodeOrder = "random"
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
    def from_dict(cls, doc: Mapping[str, Any]) -> TileSpec:
        """The spec a store recorded; one written before ``node_order`` existed kept input order."""
        return cls(**{"node_order": "input", **doc})


@dataclass(frozen=True)
class NodeInfo:
    """One node: the points of one level in one octree cube of a tile (siteline.tiles.layout). Bounds
    (of its points) in site-local metres; ``start``/``count`` index the tile's arrays; ``spacing_m``
    is the level's cube edge; ``cell``: the octree cube (None: the whole tile, stores written before
    octree nodes)."""

    key: str
    tile: str
    level: int
    bounds_min: tuple[float, float, float]
    bounds_max: tuple[float, float, float]
    count: int
    start: int
    spacing_m: float
    cell: tuple[int, int, int] | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> NodeInfo:
        """From its JSON form (store attributes, worker results)."""
        cell = doc.get("cell")
        return cls(
            **{
                **doc,
                "bounds_min": tuple(doc["bounds_min"]),
                "bounds_max": tuple(doc["bounds_max"]),
                "cell": tuple(cell) if cell is not None else None,
            }
        )


@dataclass(frozen=True)
class SceneTiling:
    """What tiling a scene recorded (``scene.statistics["tiles"]``): the store's address, spec and
    checksum (a label-set store follows the order it implies), its generation (0 until the scene is
    tiled again; part of its pairs' output keys), and counts: points, tiles, levels, bytes on disk,
    seconds spent."""

    uri: str
    spec: TileSpec
    checksum: str
    generation: int
    points: int
    tiles: int
    levels: int
    bytes: int
    seconds: float

    @property
    def bytes_per_point(self) -> float:
        return self.bytes / max(self.points, 1)

    def to_dict(self) -> dict[str, Any]:
        doc = {f.name: getattr(self, f.name) for f in fields(self)}
        return doc | {"spec": self.spec.to_dict(), "bytes_per_point": self.bytes_per_point}

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> SceneTiling:
        return cls(
            uri=doc["uri"],
            spec=TileSpec.from_dict(doc["spec"]),
            checksum=doc["checksum"],
            generation=int(doc.get("generation", 0)),
            points=int(doc["points"]),
            tiles=int(doc["tiles"]),
            levels=int(doc["levels"]),
            bytes=int(doc["bytes"]),
            seconds=float(doc.get("seconds", 0.0)),
        )


@dataclass(frozen=True)
class TileSource:
    """What a reader needs to open a scene's tile store: its address, spec, node index and checksum
    (what a label-set store must have been made for), and the stores of attributes read beside the
    tile arrays (``class`` of a label-set version, ``change`` of a pair's labels), each laid out as
    ``tiles/<tile>/<name>``."""

    uri: str
    spec: TileSpec
    nodes: tuple[NodeInfo, ...]
    checksum: str | None = None
    attributes: Mapping[str, str] = field(default_factory=dict)
