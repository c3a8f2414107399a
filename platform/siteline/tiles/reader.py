"""Reading a scene's tile store: regions, levels of detail, and exactly what a view needs."""

from __future__ import annotations

import asyncio
import math
import threading
from collections import OrderedDict
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal, NamedTuple, cast

import numpy as np
import zarr
from zarr.core.sync import sync

from siteline.camera.pinhole import Camera
from siteline.errors import TileError
from siteline.pointpass import dequantise
from siteline.records.tiling import NodeTable, TileSource, TileSpec
from siteline.schema import json_object
from siteline.stores import join, open_store
from siteline.tiles import codecs as _codecs  # noqa: F401  (quiets zarr's warning on the codecs it reads)
from siteline.tiles.chunks import DirectChunks, direct_chunks, read_chunks
from siteline.tiles.index import read_index
from siteline.tiles.layout import (
    ATTRIBUTES,
    COUNTS,
    LEGACY_COUNTS,
    METRES,
    parse_tile_key,
    tile_origin_local,
)

DEFAULT_ATTRIBUTES = ("rgb", "class")


@dataclass
class ReadStats:
    """What one read cost: tiles and points read, points decoded from the store (the inner chunks
    that were not cached), points returned (after culling), and the deepest level read per tile."""

    tiles_read: int = 0
    points_read: int = 0
    points_decoded: int = 0
    points_returned: int = 0
    levels: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class Points:
    """Points read from a scene's tiles: ``xyz_m`` (N, 3) float64 site-local metres (render them as
    float32: site-local float32 keeps millimetres), the requested attributes by name ((N,) or (N, C)
    arrays in the store's dtypes), what the read cost and, for a view's read, ``spacing_m`` (N,)
    float32: the spacing in metres of the points read around each one (what a world splat covers)."""

    xyz_m: np.ndarray
    attributes: dict[str, np.ndarray]
    stats: ReadStats
    spacing_m: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.xyz_m)

    def select(self, keep: np.ndarray) -> Points:
        """The points where ``keep`` (a mask or indices) holds; ``stats.points_returned`` follows."""
        xyz = self.xyz_m[keep]
        stats = replace(self.stats, points_returned=len(xyz))
        spacing = None if self.spacing_m is None else self.spacing_m[keep]
        return Points(xyz, {k: v[keep] for k, v in self.attributes.items()}, stats, spacing)


def bounds_box(bounds: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of 4 (x y) or 6 (x y z) bound values, site-local metres; z open when omitted."""
    b = [float(v) for v in bounds]
    if len(b) == 4:
        return np.array([b[0], b[1], -np.inf]), np.array([b[2], b[3], np.inf])
    if len(b) == 6:
        return np.array(b[:3]), np.array(b[3:])
    raise TileError(f"bounds need 4 (xmin ymin xmax ymax) or 6 (with z) numbers, got {len(b)}.")


def in_bounds(xyz: np.ndarray, bounds: Sequence[float]) -> np.ndarray:
    lo, hi = bounds_box(bounds)
    return np.all((xyz >= lo) & (xyz <= hi), axis=1)


def _box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def box_in_frustum(planes: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Conservative test: False only when the box lies wholly outside one plane."""
    corners = _box_corners(lo, hi)
    vals = corners @ planes[:, :3].T + planes[:, 3]
    return bool((vals >= 0).any(axis=0).all())


def _corner_values(planes: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(M, 8, P): each plane's value at each corner of M boxes (M, 3) lo and hi."""
    corners = np.stack(
        [np.stack([lo[:, 0] if a == 0 else hi[:, 0], lo[:, 1] if b == 0 else hi[:, 1], lo[:, 2] if c == 0 else hi[:, 2]], axis=1)
         for a in (0, 1) for b in (0, 1) for c in (0, 1)],
        axis=1,
    )  # (M, 8, 3)  # fmt: skip
    return corners @ planes[:, :3].T + planes[:, 3]


def boxes_in_frustum(planes: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(M,) bool, vectorised :func:`box_in_frustum` over M boxes (M, 3) lo and hi."""
    inside: np.ndarray = np.all(np.any(_corner_values(planes, lo, hi) >= 0, axis=1), axis=1)
    return inside


# a box counts as wholly inside a frustum when every corner is at least this far (metres) inside
# every plane: float64 rounding of a point's test (about 1e-12 m here) cannot then put a point of
# the box outside
INSIDE_MARGIN_M = 1e-6


def boxes_inside_frustum(planes: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(M,) bool: the boxes (M, 3) lo and hi that lie wholly inside the frustum ``planes`` (with
    :data:`INSIDE_MARGIN_M`): every point in them passes its test, so none needs one."""
    inside: np.ndarray = np.all(_corner_values(planes, lo, hi) >= INSIDE_MARGIN_M, axis=(1, 2))
    return inside


def box_distance(point: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Distance (m) from a point to an axis-aligned box (0 inside)."""
    d = np.maximum(np.maximum(lo - point, 0.0), point - hi)
    return float(np.linalg.norm(d))


def _open(uri: str, what: str, fix: str) -> zarr.Group:
    """The Zarr group at ``uri`` (a local path or an fsspec URL), or a TileError saying it is missing."""
    store = open_store(uri)
    if not store.exists(join(uri, "zarr.json")):
        raise TileError(f"{what} {uri} is missing: {fix}.")
    return store.open_group(uri, mode="r")


# a view's per-tile choice: (indices into the tile's nodes, points to read of each)
Selection = dict[str, tuple[np.ndarray, np.ndarray]]
# a level whose next level holds at least this many times its points still resolves the surface
# (each point its own cube): a surface's cubes are four times as many per level, a volume's eight
_RESOLVED_GROWTH = 2.0
_MIN_LEVEL_POINTS = 16


def node_positions(starts: np.ndarray, take: np.ndarray) -> np.ndarray:
    """(sum(take),) int64 positions in a tile's arrays of the first ``take[k]`` points of the nodes
    starting at ``starts[k]``, node after node."""
    return np.repeat(starts - np.r_[0, np.cumsum(take)[:-1]], take) + np.arange(int(take.sum()))


class ViewNodes(NamedTuple):
    """What a view reads: per tile, the nodes and how many points of each (``selection``); the
    frustum's planes (6, 4); and per tile, per selected node, the spacing in metres of the points
    read there (``spacing_m``: the level of detail's, or the data's own where they are sparser)."""

    selection: Selection
    planes: np.ndarray
    spacing_m: dict[str, np.ndarray]


def native_spacing_m(level_points: np.ndarray, spec: TileSpec) -> tuple[float, float] | None:
    """A tile's own point spacing (metres) and surface area (m2) from its points per level, or None
    when it holds too few: level L keeps one point of each cube of edge ``spec.spacing(L)`` that
    still holds one, so a level that the next still outgrows (:data:`_RESOLVED_GROWTH`) has a point
    in every cube the surface crosses, and ``points x edge**2`` is the surface's area; the spacing
    is ``sqrt(area / points)`` over all the tile's points. The deepest such level is taken (the
    finest cubes fit the surface best)."""
    counts = np.asarray(level_points, dtype=np.float64)
    total = counts.sum()
    for level in range(len(counts) - 2, -1, -1):
        c = counts[level]
        if c >= _MIN_LEVEL_POINTS and counts[level + 1] >= _RESOLVED_GROWTH * c:
            area = c * spec.spacing(level) ** 2
            return math.sqrt(area / total), area
    return None


@dataclass(frozen=True)
class TileNodes:
    """One tile's nodes as arrays, in array order: bounds ``lo``/``hi`` (N, 3) site-local metres,
    ``first_level``/``level`` (the band), ``start``/``count``, and ``below[:, L]`` (N, levels + 1):
    a node's points at levels under L (its first ``below[:, L]`` points are exactly those levels)."""

    lo: np.ndarray
    hi: np.ndarray
    first_level: np.ndarray
    level: np.ndarray
    start: np.ndarray
    count: np.ndarray
    below: np.ndarray

    @classmethod
    def of(cls, table: NodeTable) -> TileNodes:
        o = np.argsort(table.start, kind="stable")
        t = table.rows(o)
        below = np.zeros((len(t), t.level_counts.shape[1] + 1), np.int64)
        np.cumsum(t.level_counts, axis=1, out=below[:, 1:])
        return cls(
            t.lo, t.hi, t.first_level.astype(np.int64), t.level.astype(np.int64), t.start, t.count, below
        )

    def __len__(self) -> int:
        return len(self.start)

    def up_to(self, level: np.ndarray | int) -> np.ndarray:
        """Per node, its points at levels up to ``level`` (per node or one for all)."""
        cap = np.clip(np.asarray(level, dtype=np.int64) + 1, 0, self.below.shape[1] - 1)
        return self.below[np.arange(len(self)), np.broadcast_to(cap, (len(self),))]


@dataclass(frozen=True)
class AllNodes:
    """Every node of a scene in one set of arrays (tiles in sorted order, each tile's nodes in array
    order), for choices made across all tiles at once: ``tile`` (K,) the position of its tile in
    ``tiles``, ``index`` (K,) its index in ``by_tile[tile]``, bounds ``lo``/``hi`` (K, 3), ``level``,
    ``count``, ``start`` (in its tile's arrays), ``below`` (K, levels + 1) as :class:`TileNodes`,
    and per tile its points per level (T, 64) and their running sum."""

    tiles: tuple[str, ...]
    tile: np.ndarray
    index: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    level: np.ndarray
    count: np.ndarray
    start: np.ndarray
    below: np.ndarray
    totals: np.ndarray
    cum: np.ndarray

    @classmethod
    def of(cls, by_tile: Mapping[str, TileNodes], level_totals: Mapping[str, np.ndarray]) -> AllNodes:
        tiles = tuple(sorted(by_tile))
        parts = [by_tile[t] for t in tiles]
        width = max((p.below.shape[1] for p in parts), default=1)

        def cat(name: str) -> np.ndarray:
            return np.concatenate([getattr(p, name) for p in parts]) if parts else np.zeros(0, np.int64)

        below = (
            np.concatenate(
                [np.pad(p.below, ((0, 0), (0, width - p.below.shape[1])), mode="edge") for p in parts]
            )
            if parts
            else np.zeros((0, width), np.int64)
        )
        totals = np.array([level_totals[t] for t in tiles]) if tiles else np.zeros((0, 64))
        return cls(
            tiles, np.repeat(np.arange(len(tiles)), [len(p) for p in parts]),
            np.concatenate([np.arange(len(p)) for p in parts]) if parts else np.zeros(0, np.int64),
            cat("lo").reshape(-1, 3), cat("hi").reshape(-1, 3), cat("level"), cat("count"), cat("start"), below,
            totals, np.cumsum(totals, axis=1),
        )  # fmt: skip


class SceneTiles:
    """A scene's tile store opened for reading, indexed by its node table. Reads return :class:`Points`
    (site-local float64 metres, from the int32 counts and the tile origins).

    ``attributes``: name -> address of a Zarr group laid out like this store's ``tiles/<tile>/<name>``
    and aligned point for point with it (``class`` of a label-set version, ``change`` of a pair's
    labels), read in place of (or beside) the store's own arrays. A reader's attributes are fixed:
    :meth:`with_attribute` returns another reader."""

    def __init__(
        self,
        uri: str | Path,
        nodes: NodeTable | None = None,
        spec: TileSpec | None = None,
        cache_bytes: int = 256 * 2**20,
        attributes: Mapping[str, str] | None = None,
    ) -> None:
        """``nodes``/``spec``: the store's index and spec when the caller has them (None: read from
        the store)."""
        self.uri = str(uri)
        self.root = _open(self.uri, "tile store", "re-run `siteline scene tile`")
        if nodes is None or spec is None:
            attrs = dict(self.root.attrs)
            if "spec" not in attrs:
                raise TileError(f"{uri} is not a siteline tile store.")
            spec = spec or TileSpec.from_dict(json_object(attrs["spec"], f"tile store {uri}: spec"))
            nodes = nodes if nodes is not None else read_index(self.root, attrs, spec, self.uri)
        self.spec = spec
        self.nodes = nodes
        self.attributes = dict(attributes or {})
        self._extra = {
            name: _open(str(u), "attribute store", "process the pair again")
            for name, u in self.attributes.items()
        }
        # per tile, its nodes as arrays in array order
        self.by_tile: dict[str, TileNodes] = {
            key: TileNodes.of(nodes.rows(nodes.tile == k)) for k, key in enumerate(nodes.tiles)
        }
        self.by_tile = {k: v for k, v in self.by_tile.items() if len(v)}
        self.tile_bounds = {t: (v.lo.min(axis=0), v.hi.max(axis=0)) for t, v in self.by_tile.items()}
        self._spacing = np.array([spec.spacing(v) for v in range(64)])
        # per tile, its points per level (index = level), for partial reads of a level
        self.level_totals = {
            t: np.pad(np.diff(v.below, axis=1).sum(axis=0), (0, 64))[:64] for t, v in self.by_tile.items()
        }
        self.native_spacing = self._native_spacings()
        self.all_nodes = AllNodes.of(self.by_tile, self.level_totals)
        held = np.flatnonzero(nodes.level_counts.sum(axis=0)) if len(nodes) else np.zeros(1, np.int64)
        self._levels = held.astype(np.int64) if len(held) else np.zeros(1, np.int64)
        self._handles: dict[tuple[str, str], zarr.Array] = {}
        self._direct: dict[tuple[str, str], DirectChunks | None] = {}
        # many views of one pair read the same tiles: keep recent inner chunks (LRU, byte budget)
        self.cache_bytes = cache_bytes
        self._cache: OrderedDict[tuple[str, str, int], np.ndarray] = OrderedDict()
        self._cached = 0
        self._lock = threading.Lock()  # the cache, for a reader read from two threads at once

    def _native_spacings(self) -> dict[str, float]:
        """Each tile's own point spacing in metres (:func:`native_spacing_m`); a tile too sparse to
        tell takes the scene's (its tiles' area over their points), or the finest level's spacing."""
        found = {t: native_spacing_m(v, self.spec) for t, v in self.level_totals.items()}
        known = [(t, f) for t, f in found.items() if f is not None]
        points = sum(float(self.level_totals[t].sum()) for t, _ in known)
        area = sum(f[1] for _, f in known)
        fallback = math.sqrt(area / points) if points else self.spec.min_spacing_m
        return {t: (f[0] if f is not None else fallback) for t, f in found.items()}

    @classmethod
    def from_source(cls, source: TileSource, cache_bytes: int = 256 * 2**20) -> SceneTiles:
        """The reader of a scene's tiles as the catalog describes them (siteline.records.tiling.TileSource)."""
        return cls(source.uri, None, source.spec, cache_bytes, source.attributes)

    def attribute_record(self, name: str) -> dict[str, object]:
        """The attributes (metadata) of the group attribute ``name`` is read from."""
        if name not in self._extra:
            raise TileError(f"this reader of {self.uri} reads no attribute {name!r} from another store.")
        return dict(self._extra[name].attrs)

    @classmethod
    def open(cls, uri: str | Path) -> SceneTiles:
        """Open from the store alone (it holds the spec and the node index)."""
        return cls(uri)

    def with_attribute(self, name: str, uri: str) -> SceneTiles:
        """A reader of the same store that reads attribute ``name`` from the group at ``uri`` (laid
        out as ``tiles/<tile>/<name>``, aligned point for point with this store)."""
        return SceneTiles(self.uri, self.nodes, self.spec, self.cache_bytes, self.attributes | {name: uri})

    def _direct_of(self, tile: str, name: str) -> DirectChunks | None:
        """The direct reader of ``tiles/<tile>/<name>``'s chunks (siteline.tiles.chunks), None where
        zarr reads them."""
        key = (tile, name)
        if key not in self._direct:
            self._direct[key] = direct_chunks(self._handle(tile, name))
        return self._direct[key]

    def _handle(self, tile: str, name: str) -> zarr.Array:
        """The Zarr array ``tiles/<tile>/<name>``, opened once (each open reads metadata: a request
        per level of the hierarchy on an object store)."""
        key = (tile, name)
        arr = self._handles.get(key)
        if arr is None:
            src = self._extra.get(name, self.root)
            try:
                found = src[f"tiles/{tile}/{name}"]
            except KeyError:
                if name != COUNTS:
                    raise
                found = src[f"tiles/{tile}/{LEGACY_COUNTS}"]  # a store written before the rename
            if not isinstance(found, zarr.Array):
                raise TileError(f"{self.uri}: tiles/{tile}/{name} is not an array: the store is damaged.")
            arr = self._handles[key] = found
        return arr

    def _chunk_plan(self, tile: str, k: int, idx: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
        """The inner chunks (ascending) that values ``idx`` (ascending; the first ``k`` when None) of
        ``tile``'s arrays lie in, and each value's position in those chunks laid end to end (None:
        the first ``k``). Every array of a tile has the same chunk length (``spec.chunk_points``)."""
        c = int(self._handle(tile, COUNTS).chunks[0])
        if idx is None:
            return np.arange(-(-k // c)), None
        q = idx // c
        if len(q) and np.any(q[1:] < q[:-1]):
            raise TileError("node reads must come in array order.")
        first = np.empty(len(q), dtype=bool)
        first[:1] = True
        np.not_equal(q[1:], q[:-1], out=first[1:])
        # every chunk but the array's last is full, so chunk j of the read starts at j * c
        return q[first], (np.cumsum(first) - 1) * c + (idx - q * c)

    def _values(
        self,
        tile: str,
        name: str,
        k: int,
        plan: tuple[np.ndarray, np.ndarray | None],
        blocks: dict[tuple[str, str, int], np.ndarray],
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """Values of ``tiles/<tile>/<name>`` at ``plan`` (:meth:`_chunk_plan` of its first ``k`` or
        its chosen values), from the decoded inner chunks ``blocks`` (:meth:`_load`); written into
        ``out`` when given (chosen values only: a slice of a read's output)."""
        ids, at = plan
        if (k if at is None else len(at)) == 0:
            arr = self._handle(tile, name)
            return np.zeros((0, *arr.shape[1:]), dtype=arr.dtype)
        parts = [blocks[(tile, name, i)] for i in ids.tolist()]
        if at is None:
            return parts[0][:k] if len(parts) == 1 else np.concatenate(parts)[:k]
        if len(parts) == 1:
            return parts[0][at] if out is None else np.take(parts[0], at, axis=0, out=out)
        # chunk by chunk: a view takes a part of each, and copying whole chunks end to end first cost
        # more than the gather
        c = len(parts[0])
        edges = np.searchsorted(at, np.arange(len(parts) + 1) * c)
        if out is None:
            out = np.empty((len(at), *parts[0].shape[1:]), dtype=parts[0].dtype)
        for m, part in enumerate(parts):
            lo, hi = edges[m], edges[m + 1]
            np.take(part, at[lo:hi] - m * c, axis=0, out=out[lo:hi])
        return out

    def _load(
        self, wanted: Sequence[tuple[str, str, np.ndarray]], stats: ReadStats
    ) -> dict[tuple[str, str, int], np.ndarray]:
        """The decoded inner chunks ``(tile, name, ids)`` of ``wanted``: from the reader's LRU cache,
        the rest read straight off a local store's shards and decoded by blosc in threads
        (siteline.tiles.chunks), or, for arrays of another layout or store, in one concurrent zarr
        call (each run of consecutive missing chunks of an array one selection), then cached. A
        view's read of dozens of tiles and attributes waits for the slowest chunk, not for the sum of
        them. One load at a time per reader (a pair of a scene with itself renders
        both sides from one reader, in two threads)."""
        with self._lock:
            return self._load_locked(wanted, stats)

    def _load_locked(
        self, wanted: Sequence[tuple[str, str, np.ndarray]], stats: ReadStats
    ) -> dict[tuple[str, str, int], np.ndarray]:
        out: dict[tuple[str, str, int], np.ndarray] = {}
        runs: list[tuple[str, str, int, int, int]] = []  # tile, name, chunk length, first, last
        for tile, name, ids in wanted:
            c = int(self._handle(tile, name).chunks[0])
            missing = []
            for i in ids.tolist():
                key = (tile, name, i)
                hit = self._cache.get(key)
                if hit is None:
                    missing.append(i)
                else:
                    self._cache.move_to_end(key)
                    out[key] = hit
            if missing:
                m = np.array(missing)
                for run in np.split(m, np.flatnonzero(np.diff(m) != 1) + 1):
                    runs.append((tile, name, c, int(run[0]), int(run[-1])))
        fast: list[tuple[DirectChunks, int]] = []
        keys: list[tuple[str, str, int]] = []
        slow: list[tuple[str, str, int, int, int]] = []
        for spans in runs:
            tile, name, _, first, last = spans
            d = self._direct_of(tile, name)
            if d is None:
                slow.append(spans)
                continue
            fast += [(d, i) for i in range(first, last + 1)]
            keys += [(tile, name, i) for i in range(first, last + 1)]
        if fast:  # straight off the disk (siteline.tiles.chunks)
            for key, block in zip(keys, read_chunks(fast), strict=True):
                stats.points_decoded += len(block)
                out[key] = self._cache[key] = block
                self._cached += block.nbytes
        if slow:
            arrays = [self._handle(tile, name).async_array for tile, name, _, _, _ in slow]

            async def read_all() -> list[Any]:
                return await asyncio.gather(
                    *(
                        a.getitem(slice(first * c, (last + 1) * c))
                        for a, (_, _, c, first, last) in zip(arrays, slow, strict=True)
                    )
                )

            for (tile, name, c, first, last), got in zip(slow, sync(read_all()), strict=True):
                values = np.asarray(got)
                stats.points_decoded += len(values)
                for i in range(first, last + 1):
                    lo = (i - first) * c
                    block = values[lo : lo + c]
                    block = block.copy() if last > first else block  # evictable one by one
                    out[(tile, name, i)] = self._cache[(tile, name, i)] = block
                    self._cached += block.nbytes
        while self._cached > self.cache_bytes and self._cache:
            _, old = self._cache.popitem(last=False)
            self._cached -= old.nbytes
        return out

    @property
    def point_count(self) -> int:
        return self.nodes.points

    def level_for_resolution(self, resolution_m: float) -> int:
        """Smallest level whose spacing is at most ``resolution_m`` (the deepest if none is)."""
        return int(self.levels_for_resolutions(np.array([resolution_m]))[0])

    def prefix(self, tile: str) -> int:
        """How many points ``tile`` holds."""
        return int(self.by_tile[tile].count.sum())

    def read(self, prefixes: Mapping[str, int], attributes: Sequence[str]) -> Points:
        """Read the first ``prefixes[tile]`` points of each tile's arrays: one call per tile and attribute."""
        return self._gather({t: (k, None) for t, k in prefixes.items() if k > 0}, attributes)

    def read_tile(self, tile: str, attributes: Sequence[str], level: int | None = None) -> Points:
        """Every point of ``tile`` up to ``level`` (all levels when None), in the store's order."""
        if level is None:
            return self.read({tile: self.prefix(tile)}, attributes)
        return self.read_nodes(self._up_to(tile, level), attributes)

    def _up_to(self, tile: str, level: int) -> Selection:
        """The selection of every point of ``tile`` at levels up to ``level``."""
        take = self.by_tile[tile].up_to(level)
        sel = np.flatnonzero(take)
        return {tile: (sel, take[sel])} if len(sel) else {}

    def tile_blocks(
        self, tile: str, attributes: Sequence[str], dtype: type = np.float32, block_points: int = 1 << 20
    ) -> Iterator[tuple[int, np.ndarray, dict[str, np.ndarray]]]:
        """``tile``'s points block by block (about ``block_points``, whole shards), past the chunk cache:
        (the block's first index, (n, 3) site-local metres in ``dtype``, its ``attributes``), the values
        of :meth:`read_tile` (cast when ``dtype`` is float32). For passes over whole tiles that read each
        once (the change labels, their spacing): a read through the cache holds the raw counts, the
        float64 metres and the cached chunks at once (1.4 GB more on a 20 M point tile), and leaves 256
        MB of chunks cached that no later read of the pass wants."""
        self._check_attributes(attributes)
        n = self.prefix(tile)
        i, j = parse_tile_key(tile)
        origin = tile_origin_local(i, j, self.spec.tile_size_m)
        counts = self._handle(tile, COUNTS)
        arrays = {a: self._handle(tile, a) for a in attributes}
        unit = int((counts.shards or counts.chunks)[0])
        step = max(unit, block_points // unit * unit)
        for lo in range(0, n, step):
            hi = min(n, lo + step)
            xyz: np.ndarray = dequantise(np.asarray(counts[lo:hi]), origin, self.spec.quantum_m).astype(
                dtype, copy=False
            )
            yield lo, xyz, {a: np.asarray(arr[lo:hi]) for a, arr in arrays.items()}

    def read_tile_uncached(
        self, tile: str, attributes: Sequence[str], dtype: type = np.float32, block_points: int = 1 << 20
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Every point of ``tile`` as (N, 3) site-local metres in ``dtype`` and its ``attributes``,
        filled from :meth:`tile_blocks` (the result and one block held, nothing cached)."""
        self._check_attributes(attributes)
        n = self.prefix(tile)
        xyz: np.ndarray = np.empty((n, 3), dtype)
        out = {
            a: np.empty((n, *self._handle(tile, a).shape[1:]), self._handle(tile, a).dtype)
            for a in attributes
        }
        for lo, block, attrs in self.tile_blocks(tile, attributes, dtype, block_points):
            xyz[lo : lo + len(block)] = block
            for a, values in attrs.items():
                out[a][lo : lo + len(block)] = values
        return xyz, out

    def _check_attributes(self, attributes: Sequence[str]) -> None:
        bad = [a for a in attributes if (a not in ATTRIBUTES or a == COUNTS) and a not in self.attributes]
        if bad:
            raise TileError(
                f"unknown attributes {bad}; choose from {[a for a in ATTRIBUTES if a != COUNTS]} "
                f"(positions always come back as {METRES!r})."
            )

    def _gather(self, plan: dict[str, tuple[int, np.ndarray | None]], attributes: Sequence[str]) -> Points:
        """Per tile of ``plan``: read values ``idx`` of its arrays (the first ``k`` when None; by
        cached chunk, :meth:`_values`), dequantise ``xyz_counts`` to site-local float64 metres;
        concatenate over tiles."""
        self._check_attributes(attributes)
        stats = ReadStats()
        parts: dict[str, list[np.ndarray]] = {a: [] for a in (METRES, *attributes)}
        names = [COUNTS if a == METRES else a for a in (METRES, *attributes)]
        chunks = {t: self._chunk_plan(t, *plan[t]) for t in sorted(plan)}
        blocks = self._load([(t, n, chunks[t][0]) for t in sorted(plan) for n in names], stats)
        for tile in sorted(plan):
            k, idx = plan[tile]
            i, j = parse_tile_key(tile)
            origin = tile_origin_local(i, j, self.spec.tile_size_m)
            xyz = dequantise(self._values(tile, COUNTS, k, chunks[tile], blocks), origin, self.spec.quantum_m)
            parts[METRES].append(xyz)
            for a in attributes:
                parts[a].append(self._values(tile, a, k, chunks[tile], blocks))
            stats.tiles_read += 1
            stats.points_read += k if idx is None else len(idx)
        # one tile's metres are a fresh array: no copy (its attributes may be the cache's own chunks)
        out = {
            a: (chunks[0] if len(chunks) == 1 and a == METRES else np.concatenate(chunks))
            if chunks
            else self._empty(a)
            for a, chunks in parts.items()
        }
        stats.points_returned = len(out[METRES])
        return Points(out.pop(METRES), out, stats)

    def _gather_view(self, plan: dict[str, np.ndarray], attributes: Sequence[str], view: ViewNodes) -> Points:
        """The points ``plan[tile]`` (positions in the tile's arrays, ascending) of the ``view`` whose
        selection made the plan, each with its node's spacing (``spacing_m``): per decoded chunk, a
        compiled pass (siteline.tiles.kernels.place_points) makes its chosen points metres, tests
        those of nodes that cross a plane of the frustum (a node wholly inside keeps all, float64) and
        writes the kept ones straight into the read's output; then the attributes of the kept points
        only, into theirs (no concatenation over tiles)."""
        from siteline.tiles.kernels import place_points

        self._check_attributes(attributes)
        stats = ReadStats()
        tiles = sorted(plan)
        chunks = {t: self._chunk_plan(t, 0, plan[t]) for t in tiles}
        blocks = self._load([(t, n, chunks[t][0]) for t in tiles for n in (COUNTS, *attributes)], stats)
        total = sum(len(idx) for idx in plan.values())
        xyz, rows = np.empty((total, 3), np.float64), np.empty(total, np.int64)
        spacing = np.empty(total, np.float32)
        values = {a: np.empty((total, *e.shape[1:]), e.dtype) for a in attributes for e in [self._empty(a)]}
        n = 0
        for tile in tiles:
            ids, at = chunks[tile][0], cast(np.ndarray, chunks[tile][1])  # chosen values: never None
            i, j = parse_tile_key(tile)
            frame = np.r_[
                np.asarray(tile_origin_local(i, j, self.spec.tile_size_m), np.float64), self.spec.quantum_m
            ]
            sel, take = view.selection[tile]
            nodes = self.by_tile[tile]
            crossing = np.repeat(~boxes_inside_frustum(view.planes, nodes.lo[sel], nodes.hi[sel]), take)
            c = int(self._handle(tile, COUNTS).chunks[0])
            edges = np.searchsorted(at, np.arange(len(ids) + 1) * c)
            start = n
            for m, chunk in enumerate(ids.tolist()):
                lo, hi, first = int(edges[m]), int(edges[m + 1]), n
                n = place_points(
                    blocks[(tile, COUNTS, chunk)], at[lo:hi] - m * c, crossing[lo:hi], frame, view.planes, xyz, rows, n
                )  # fmt: skip
                rows[first:n] += lo
            kept = rows[start:n]
            spacing[start:n] = np.repeat(view.spacing_m[tile], take)[kept]
            for a in attributes:
                self._values(tile, a, n - start, (ids, at[kept]), blocks, values[a][start:n])
            stats.tiles_read += 1
            stats.points_read += len(at)
        stats.points_returned = n
        return Points(xyz[:n], {a: v[:n] for a, v in values.items()}, stats, spacing[:n])

    def _empty(self, attribute: str) -> np.ndarray:
        if attribute == METRES:
            return np.zeros((0, 3), np.float64)
        arr = self._handle(next(iter(self.by_tile)), attribute)
        return np.zeros((0, *arr.shape[1:]), dtype=arr.dtype)

    def points(
        self,
        bounds: Sequence[float] | None = None,
        level: int | None = None,
        resolution: float | None = None,
        attributes: Sequence[str] = DEFAULT_ATTRIBUTES,
    ) -> Points:
        """Points in ``bounds`` ((xmin, ymin, xmax, ymax) or 6 values with z, site-local metres) up to
        ``level`` (or the level that reaches ``resolution`` metres; all levels when both are None).
        In a store whose node prefixes span their nodes (``spec.partial_levels``), ``resolution``
        reads the level that crosses it in part, as a view does (:meth:`node_takes`), so the result
        has about that spacing whatever the density."""
        if level is not None and resolution is not None:
            raise TileError("give level or resolution, not both.")
        if resolution is not None and not self.spec.partial_levels:
            level, resolution = self.level_for_resolution(resolution), None
        lo = hi = None
        if bounds is not None:
            lo, hi = bounds_box(bounds)
        tiles = [
            t
            for t, (tlo, thi) in self.tile_bounds.items()
            if lo is None or hi is None or not (np.any(thi < lo) or np.any(tlo > hi))
        ]
        if resolution is not None:
            selection: Selection = {}
            for tile in tiles:
                need = np.full(len(self.by_tile[tile]), float(resolution))
                sel, take = self.node_takes(tile, np.ones(len(need), bool), need)
                if len(sel):
                    selection[tile] = (sel, take)
            out = self.read_nodes(selection, attributes)
        elif level is not None:
            out = self.read_nodes({k: v for t in tiles for k, v in self._up_to(t, level).items()}, attributes)
        else:
            out = self.read({t: self.prefix(t) for t in tiles}, attributes)
        return out.select(in_bounds(out.xyz_m, bounds)) if bounds is not None else out

    def nodes_near(self, centers: np.ndarray, radius_m: float) -> np.ndarray:
        """Positions into :attr:`all_nodes` (ascending) of the nodes whose bounds lie within
        ``radius_m`` of one of ``centers`` ((M, 3) site-local metres)."""
        a = self.all_nodes
        q = np.atleast_2d(np.asarray(centers, dtype=np.float64))
        near = np.zeros(len(a.lo), bool)
        for start in range(0, len(q), 8):  # (8, K, 3) at a time: a few MB with 30k nodes
            c = q[start : start + 8, None, :]
            gap = np.maximum(np.maximum(a.lo[None] - c, 0.0), c - a.hi[None])
            near |= (np.einsum("mkd,mkd->mk", gap, gap) <= radius_m**2).any(axis=0)
        return np.flatnonzero(near)

    def points_near(
        self, centers: np.ndarray, radius_m: float, attributes: Sequence[str] = ("class",)
    ) -> Points:
        """Every point (all levels, full density) of the nodes whose bounds lie within ``radius_m`` of
        one of ``centers`` ((M, 3) site-local metres): a superset of the points within ``radius_m`` of
        them, read in one pass; nothing is read where no node is near (a camera high above the
        site). Bounds enclose their nodes' points, so no point within the radius is missed."""
        a = self.all_nodes
        rows = self.nodes_near(centers, radius_m)
        selection: Selection = {}
        for k in np.unique(a.tile[rows]):
            mine = rows[a.tile[rows] == k]
            selection[a.tiles[k]] = (a.index[mine], a.count[mine])
        return self.read_nodes(selection, attributes)

    def view_nodes(
        self, camera: Camera, scale: float, spacing_px: float = 0.5, near_m: float = 1e-3
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """What a view of ``camera`` at ``scale`` reads, over all tiles at once: positions into
        :attr:`all_nodes` of the nodes its frustum meets, how many points of each
        (:meth:`levels_for_view`), each node's spacing read in metres, and the frustum's planes."""
        cam = camera.scaled(scale)
        planes = cam.frustum_planes(near_m)
        a = self.all_nodes
        if not len(a.lo):
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), planes
        inside = boxes_in_frustum(planes, a.lo, a.hi)
        centre = cam.center
        dist = np.linalg.norm(np.maximum(np.maximum(a.lo - centre, 0.0), centre - a.hi), axis=1)
        need = spacing_px * np.maximum(dist, near_m) / min(cam.fx, cam.fy)
        take = self.takes(np.arange(len(a.lo)), need)
        sel = np.flatnonzero(inside & (take > 0))
        native = np.array([self.native_spacing[t] for t in a.tiles])[a.tile[sel]]
        return sel, take[sel], np.maximum(need[sel], native), planes

    def levels_for_view(
        self, camera: Camera, scale: float, spacing_px: float = 0.5, near_m: float = 1e-3
    ) -> ViewNodes:
        """Per tile met by the frustum of ``camera`` at ``scale``: ``(indices, take)``, the nodes to
        read (indices into ``by_tile[tile]``) and how many of each node's points, so that each node's
        surface is read at a spacing of ``spacing_px`` pixel footprints at its nearest distance; the
        frustum's planes; and per selected node the spacing read there in metres, that spacing or
        the tile's own (:attr:`native_spacing`) where the data are sparser.

        Levels coarser than that spacing are read whole. In a store whose node prefixes span their
        nodes (``spec.partial_levels``: any order but "input") the level that crosses it is read in
        part: the first ``take`` points of each of its nodes, ``take / count = (r - 1) N_<a / N_a``
        with ``r = (spacing(a-1) / need)**2`` (a surface's density grows as 1 / spacing**2) and ``N``
        the tile's points per level, so the density read is what the footprint needs, whatever the
        data hold. Otherwise that level is read whole (1-4 points per footprint of a surface)."""
        sel, take, spacing, planes = self.view_nodes(camera, scale, spacing_px, near_m)
        a = self.all_nodes
        out: Selection = {}
        spaced: dict[str, np.ndarray] = {}
        tiles = a.tile[sel]
        for k in np.unique(tiles):
            mine = tiles == k
            out[a.tiles[k]] = (a.index[sel[mine]], take[mine])
            spaced[a.tiles[k]] = spacing[mine]
        return ViewNodes(out, planes, spaced)

    def takes(self, rows: np.ndarray, need_m: np.ndarray) -> np.ndarray:
        """How many points of each node ``rows`` (positions into :attr:`all_nodes`) to read for a
        spacing of ``need_m`` metres each (:meth:`node_takes`, across tiles)."""
        a = self.all_nodes
        allowed = self.levels_for_resolutions(need_m)
        below = a.below[rows]
        k = np.arange(len(rows))
        cap = np.minimum(allowed, below.shape[1] - 2)
        whole = below[k, cap]
        at = below[k, cap + 1] - whole
        part = at.copy()
        if self.spec.partial_levels:
            edge = (allowed > 0) & (at > 0)
            lv = allowed[edge]
            t = a.tile[rows[edge]]
            r = (self._spacing[lv - 1] / need_m[edge]) ** 2
            frac = np.clip((r - 1.0) * a.cum[t, lv - 1] / np.maximum(a.totals[t, lv], 1), 0.0, 1.0)
            part[edge] = np.maximum(np.ceil(frac * at[edge]).astype(np.int64), 1)
        return np.where(allowed > a.level[rows], a.count[rows], whole + part)

    def node_takes(
        self, tile: str, candidates: np.ndarray, need_m: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Which of ``tile``'s nodes (a mask over ``by_tile[tile]``) to read, and how many points of
        each, for a spacing of ``need_m`` metres per node: the levels coarser than it whole and, in a
        store whose node prefixes span their nodes, the level that crosses it in part (see
        :meth:`levels_for_view`); in one with input order that level whole. A node holds a band of
        levels sorted by level, so its coarse levels are a prefix of it and the part of the crossing
        level follows them."""
        nodes = self.by_tile[tile]
        allowed = self.levels_for_resolutions(need_m)
        rows = np.arange(len(nodes))
        cap = np.minimum(allowed, nodes.below.shape[1] - 2)
        whole = nodes.below[rows, cap]  # levels under the crossing one
        at = nodes.below[rows, cap + 1] - whole  # the crossing level's points in the node
        part = at.copy()
        if self.spec.partial_levels:
            edge = (allowed > 0) & (at > 0)
            a = allowed[edge]
            totals = self.level_totals[tile]
            below = np.cumsum(totals)[a - 1]
            r = (self._spacing[a - 1] / need_m[edge]) ** 2
            frac = np.clip((r - 1.0) * below / np.maximum(totals[a], 1), 0.0, 1.0)
            part[edge] = np.maximum(np.ceil(frac * at[edge]).astype(np.int64), 1)
        take = np.where(allowed > nodes.level, nodes.count, whole + part)
        sel = np.flatnonzero(candidates & (take > 0))
        return sel, take[sel]

    def levels_for_resolutions(self, resolution_m: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`level_for_resolution`."""
        levels = self._levels
        k = np.searchsorted(-self._spacing[levels], -np.asarray(resolution_m, dtype=np.float64), side="left")
        return levels[np.minimum(k, len(levels) - 1)]

    def read_nodes(
        self, selection: Selection, attributes: Sequence[str], view: ViewNodes | None = None
    ) -> Points:
        """Read, per tile, the first ``take[k]`` points of each node ``indices[k]`` of
        ``selection[tile] = (indices, take)`` (indices into ``by_tile[tile]``, ascending): only
        the inner chunks those ranges touch are decoded (:meth:`_values`). ``view``: the view
        whose selection this is, to keep only the points in its frustum (:meth:`_gather_view`)."""
        plan = {
            tile: node_positions(self.by_tile[tile].start[sel], take)
            for tile, (sel, take) in selection.items()
        }
        if view is not None:
            out = self._gather_view(plan, attributes, view)
        else:
            out = self._gather({t: (int(idx.max()) + 1, idx) for t, idx in plan.items()}, attributes)
        out.stats.levels = {t: self._deepest(t, sel, take) for t, (sel, take) in selection.items()}
        return out

    def _deepest(self, tile: str, sel: np.ndarray, take: np.ndarray) -> int:
        """The deepest level a read of the first ``take`` points of nodes ``sel`` reaches."""
        below = self.by_tile[tile].below[sel]
        return int((np.sum(below[:, 1:] < take[:, None], axis=1)).max(initial=0))

    def points_for_view(
        self,
        camera: Camera,
        scale: float,
        attributes: Sequence[str] = DEFAULT_ATTRIBUTES,
        level: int | Literal["auto"] | None = "auto",
        near_m: float = 1e-3,
        lod_factor: float = 1.0,
        point_size_px: int = 1,
    ) -> Points:
        """Points a render of ``camera`` at ``scale`` with ``point_size_px`` disks needs: nodes culled
        by the frustum, and per node the points that give a spacing of ``lod_factor`` x half a drawn
        point (``lod_factor * point_size_px / 2`` pixel footprints) at the node's nearest distance
        (``level="auto"``, the last level in part: see :meth:`levels_for_view`; an int caps every node
        at that level; None reads all levels). lod_factor 1 keeps coverage within a point of reading
        everything (~4 points read per pixel of a surface for 1 px points, ~0.5 for 3 px disks); larger
        reads fewer at some coverage cost (bench/tiles.py measures both). Stores written in input
        order read whole levels, up to 4x more. Points outside the frustum are dropped
        (float64 test), so at full level the result is exactly the brute-force frustum selection."""
        if level == "auto":
            view = self.levels_for_view(camera, scale, lod_factor * point_size_px / 2, near_m)
        else:
            view = self._frustum_nodes(camera, scale, level, near_m)
        # only the points of nodes that cross a plane are tested: a node wholly inside keeps all
        return self.read_nodes(view.selection, attributes, view)

    @staticmethod
    def spacing_of(view: ViewNodes) -> np.ndarray:
        """(N,) float32 metres: the spacing of each point a read of ``view.selection`` returns, in
        the read's order (tiles sorted, nodes as selected)."""
        parts = [np.repeat(view.spacing_m[t], view.selection[t][1]) for t in sorted(view.selection)]
        return np.concatenate(parts).astype(np.float32) if parts else np.zeros(0, np.float32)

    def _frustum_nodes(self, camera: Camera, scale: float, level: int | None, near_m: float) -> ViewNodes:
        """Every node in the frustum up to ``level`` (all when None), whole."""
        planes = camera.scaled(scale).frustum_planes(near_m)
        selection: Selection = {}
        spacing: dict[str, np.ndarray] = {}
        for tile, (tlo, thi) in self.tile_bounds.items():
            if not box_in_frustum(planes, tlo, thi):
                continue
            nodes = self.by_tile[tile]
            take = nodes.count if level is None else nodes.up_to(level)
            sel = np.flatnonzero(boxes_in_frustum(planes, nodes.lo, nodes.hi) & (take > 0))
            if len(sel):
                selection[tile] = (sel, take[sel])
                floor = 0.0 if level is None else self.spec.spacing(level)
                spacing[tile] = np.full(len(sel), max(floor, self.native_spacing[tile]))
        return ViewNodes(selection, planes, spacing)


def class_counts(tiles: SceneTiles) -> np.ndarray:
    """(256,) int64: the points of each class id in the scene's store (its label set 1)."""
    counts = np.zeros(256, dtype=np.int64)
    for tile in sorted(tiles.by_tile):
        counts += np.bincount(tiles.read_tile(tile, ("class",)).attributes["class"], minlength=256)
    return counts
