"""One tile levelled, ordered into nodes and written a few blocks at a time (runs in a worker process).

A tile's points come from the partition as slices of its blocks (columns of its level-0 cubes,
siteline.pointpass.partition). Levels are decided inside level-0 cubes with ranks seeded per block
(:func:`siteline.pointpass.lod.block_ranks`), and the node plan adds up per-cube counts
(:func:`siteline.pointpass.nodes.cube_counts`), so a tile of more than ``batch_points`` points is handled
in batches of whole blocks:

1. per batch: gather its records (the next batch is read from the run files while this one is
   worked on), level them, count them per (level, node cube); the levels go to a scratch file;
2. the tile's node plan from the counts;
3. per batch again: gather, place each point (its group's next slot), scatter the records into the
   worker's scratch file (one per worker, overwritten tile after tile) in array order;
4. the scratch file is written to the Zarr arrays shard by shard, each shard's groups read whole
   and put in node order (:meth:`siteline.pointpass.nodes.NodePlan.node_order`).

A tile that fits one batch does the same in memory. Memory is thus set by ``batch_points`` (the
batch worked on and the one read ahead), not by density, and the arrays are the same whatever the
batches (a tested property).
"""

from __future__ import annotations

import hashlib
import os
import threading
import zlib
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

import numpy as np

from siteline.config import DEFAULT_TILE_BATCH_POINTS
from siteline.errors import TileError
from siteline.pointpass import (
    RECORD,
    NodePlan,
    Slice,
    add_cube_counts,
    assign_levels,
    block_ranks,
    cube_counts,
    dequantise,
    plan_nodes,
    scatter_rows,
    split_records,
)
from siteline.records.tiling import NodeTable, TileSpec
from siteline.stores import open_store
from siteline.tiles.chunks import direct_chunks
from siteline.tiles.codecs import array_codecs, round_trips, time_scale
from siteline.tiles.layout import (
    ATTRIBUTES,
    COUNTS,
    parse_tile_key,
    tile_origin_local,
)

# a tile of more points than this is levelled and ordered a batch of blocks at a time (about 200
# bytes a point at the peak; SITELINE_TILE_BATCH_POINTS, docs/performance.md)
BATCH_POINTS = DEFAULT_TILE_BATCH_POINTS

Rows = Callable[[int, int], np.ndarray]  # records [a, b) of a tile, as placed
Columns = Callable[[int, int], dict[str, np.ndarray]]  # each attribute of rows [a, b), in node order


class WrittenTile(NamedTuple):
    """What :func:`write_tile` wrote: the tile's key, its points, the checksum of its arrays and its
    node rows."""

    key: str
    points: int
    checksum: str
    nodes: NodeTable


def tile_seed(key: str, seed: int) -> int:
    return zlib.crc32(key.encode()) ^ (seed * 2654435761 & 0xFFFFFFFF)


def batches(parts: list[Slice], budget: int) -> list[list[Slice]]:
    """Consecutive whole blocks of ``parts`` (sorted by block), each batch at most ``budget`` points
    unless one block alone holds more."""
    per_block: dict[int, int] = {}
    for p in parts:
        per_block[p.block] = per_block.get(p.block, 0) + p.points
    out: list[list[Slice]] = []
    size = 0
    for k, part in enumerate(parts):
        if (k == 0 or part.block != parts[k - 1].block) and (
            not out or size + per_block[part.block] > budget
        ):
            out.append([])
            size = 0
        out[-1].append(part)
        size += part.points
    return out


def _gather(parts: list[Slice], out: np.ndarray | None = None) -> np.ndarray:
    """A batch's records from its slices of the runs, in order (into ``out`` when given: records of
    the batch's size). Slices that lie end to end in a run file (a chunk's next blocks) are read as
    one range (``Store.read_into``: one read around the page cache, or one ranged GET of an
    fsspec URL)."""
    dest = np.r_[0, np.cumsum([p.points for p in parts])]
    out = np.empty(int(dest[-1]), RECORD) if out is None else out
    ranges: list[tuple[str, int, int, list[int]]] = []
    for k in sorted(range(len(parts)), key=lambda k: (parts[k].path, parts[k].offset)):
        _, path, offset, count, _ = parts[k]
        if ranges and ranges[-1][0] == path and ranges[-1][2] == offset:
            ranges[-1] = (path, ranges[-1][1], offset + count, [*ranges[-1][3], k])
        else:
            ranges.append((path, offset, offset + count, [k]))
    rows = _bytes(out)
    size = RECORD.itemsize
    for path, start, end, members in ranges:
        into = [rows[dest[k] : dest[k + 1]].data.cast("B") for k in members if dest[k + 1] > dest[k]]
        if open_store(path).read_into(path, start * size, into) != (end - start) * size:
            raise TileError(f"run file {path} ends early: the partition changed while tiling.")
    return out


def _gathered(groups: list[list[Slice]]) -> Iterator[np.ndarray]:
    """Each batch's records in turn: the next batch is read in a thread while the caller works on
    this one (the runs come from disk, siteline.stores.directio), into records this thread allocates."""
    with ThreadPoolExecutor(1, thread_name_prefix="siteline-gather") as ahead:

        def read(parts: list[Slice]) -> Future[np.ndarray]:
            return ahead.submit(_gather, parts, np.empty(sum(p.points for p in parts), RECORD))

        pending = [read(parts) for parts in groups[:1]]
        for k in range(len(groups)):
            rec = pending.pop().result()
            if k + 1 < len(groups):
                pending.append(read(groups[k + 1]))
            yield rec


def _levels(rec: np.ndarray, parts: list[Slice], spec: TileSpec, seed: int, z0: int) -> np.ndarray:
    """The levels of a batch's records (ranks seeded per block; z0: the tile's lowest z count)."""
    blocks = np.array([p.block for p in parts])
    counts = np.array([p.points for p in parts])
    head = np.r_[0, np.flatnonzero(blocks[1:] != blocks[:-1]) + 1]
    sizes = np.add.reduceat(counts, head) if len(parts) else counts
    order = block_ranks(sizes, [[seed, int(b)] for b in blocks[head]] if len(parts) else [])
    return assign_levels(rec[COUNTS], spec, order, z0)


def _scale(values: list[float | None]) -> float | None:
    """One gps_time scale for batches that each round-trip at theirs: the finest (pass 2 checks that
    every batch round-trips at it); None when one batch has none."""
    return None if any(v is None for v in values) else max((v for v in values if v is not None), default=1.0)


def _in_memory(
    key: str, parts: list[Slice], spec: TileSpec, seed: int, z0: int
) -> tuple[NodePlan, Columns, float | None]:
    rec = _gather(parts)
    levels = _levels(rec, parts, spec, seed, z0)
    plan = plan_nodes(cube_counts(rec[COUNTS], levels, spec), spec, spec.level_count, seed ^ 0x5EED)
    seen = np.zeros(len(plan.key), np.int64)
    where = plan.place(rec[COUNTS], levels, spec, seen)
    _check_placed(key, plan, seen)
    placed = np.empty(len(rec), RECORD)
    scatter_rows(_bytes(placed), _bytes(rec), where)
    return plan, _in_node_order(plan, lambda a, b: placed[a:b]), time_scale(placed["gps_time"])


def _bytes(rec: np.ndarray) -> np.ndarray:
    """Records (N,) as (N, itemsize) uint8 (a view)."""
    return rec.view(np.uint8).reshape(len(rec), RECORD.itemsize)


_DTYPES = [RECORD[name] for name in ATTRIBUTES]
_SIZES = np.array([dtype.itemsize for dtype in _DTYPES])


def _columns(rec: np.ndarray, order: np.ndarray) -> dict[str, np.ndarray]:
    """Each attribute of records ``rec[order]`` as its own contiguous array: views of one buffer
    (each column 8-byte aligned), filled in one pass."""
    m = len(order)
    ends = np.cumsum(-(-m * _SIZES // 8) * 8)
    buf = np.empty(int(ends[-1]), np.uint8)
    cols = {
        name: buf[a : a + m * dtype.itemsize].view(dtype.base).reshape(m, *dtype.shape)
        for name, dtype, a in zip(ATTRIBUTES, _DTYPES, np.r_[0, ends[:-1]], strict=True)
    }
    split_records(rec, order, *cols.values())
    return cols


def _in_node_order(plan: NodePlan, rows: Rows) -> Columns:
    """The columns of rows [a, b) in node order, from the rows as placed: the whole groups around
    them are read and ordered (:meth:`NodePlan.node_order`), so a write may cut groups anywhere."""

    def columns(a: int, b: int) -> dict[str, np.ndarray]:
        lo, hi = plan.groups_around(a, b)
        rec = rows(lo, hi)
        return _columns(rec, plan.node_order(rec[COUNTS], lo)[a - lo : b - lo])

    return columns


_PLACED = threading.local()  # this thread's file of placed records (_placed_file)


def _placed_file(folder: Path, size: int) -> Path:
    """This thread's scratch file of placed records in ``folder``, at least ``size`` bytes. One file
    serves every tile a worker writes, overwritten in place: on virtual machines the first write of a
    file page costs about 20x an overwrite (docs/performance.md). Whoever made ``folder`` removes it."""
    path: Path | None = getattr(_PLACED, "file", None)
    if path is None or path.parent != folder or not path.exists():
        path = folder / f".placed-{os.getpid()}-{threading.get_ident()}"
        path.touch()
        _PLACED.file = path
    if path.stat().st_size < size:
        os.truncate(path, size)
    return path


def _out_of_core(
    key: str, groups: list[list[Slice]], spec: TileSpec, seed: int, z0: int, scratch: Path, placed: Path
) -> tuple[NodePlan, Columns, float | None]:
    counted, scales = [], []
    for k, (parts, rec) in enumerate(zip(groups, _gathered(groups), strict=True)):  # pass 1: levels, counts
        levels = _levels(rec, parts, spec, seed, z0)
        np.save(scratch / f"{key}.levels-{k}.npy", levels)
        counted.append(cube_counts(rec[COUNTS], levels, spec))
        scales.append(time_scale(rec["gps_time"]))
    plan = plan_nodes(add_cube_counts(counted), spec, spec.level_count, seed ^ 0x5EED)
    scale = _scale(scales)
    sorted_path = _placed_file(placed, plan.points * RECORD.itemsize)
    seen = np.zeros(len(plan.key), np.int64)
    for k, rec in enumerate(_gathered(groups)):  # pass 2: each point to its place
        levels = np.load(scratch / f"{key}.levels-{k}.npy")
        where = plan.place(rec[COUNTS], levels, spec, seen)
        if scale is not None and not round_trips(rec["gps_time"], scale):
            scale = None
        out = np.memmap(sorted_path, dtype=np.uint8, mode="r+", shape=(plan.points, RECORD.itemsize))
        scatter_rows(out, _bytes(rec), where)
        del out  # unmapped (not flushed: a scratch file): its pages leave this process
        os.unlink(scratch / f"{key}.levels-{k}.npy")

    _check_placed(key, plan, seen)

    def rows(a: int, b: int) -> np.ndarray:
        return np.fromfile(sorted_path, dtype=RECORD, count=b - a, offset=a * RECORD.itemsize)

    return plan, _in_node_order(plan, rows), scale


def _check_placed(key: str, plan: NodePlan, seen: np.ndarray) -> None:
    """Refuse a tile whose points did not fill every slot of its plan (its runs changed under it)."""
    if not np.array_equal(seen, plan.count):
        raise TileError(
            f"tile {key}: its points do not fill its node plan; the partition changed while tiling."
        )


async def _write(
    group_path: str, key: str, plan: NodePlan, columns: Columns, spec: TileSpec, scale: float | None
) -> tuple[str, np.ndarray, np.ndarray]:
    """Write the tile's arrays shard by shard (each write covers whole shards); return the tile's
    checksum (of each array in order) and its nodes' bounds (site-local metres)."""
    import asyncio

    import zarr
    from zarr.api.asynchronous import open_group

    n, starts = plan.points, plan.node_start
    root = await open_group(store=group_path, mode="a")
    group = await (await root.require_group("tiles")).create_group(key)
    first = columns(0, min(n, 1))
    arrays = await asyncio.gather(
        *(
            group.create_array(
                name, shape=(n, *v.shape[1:]), dtype=v.dtype, chunks=(spec.chunk_points, *v.shape[1:]),
                shards=(spec.shard_points, *v.shape[1:]), fill_value=0,
                config={"write_empty_chunks": True},  # store every chunk: zarr skips its all-zero test
                **array_codecs(name, v.dtype, v.ndim, spec, scale),
            )
            for name, v in first.items()
        )
    )  # fmt: skip
    # shards of a local store are coded here (siteline.tiles.chunks: zarr's bytes in a third to a half
    # of its time); any other store's go through zarr
    direct = {arr.basename: direct_chunks(zarr.Array(arr)) for arr in arrays}
    through_zarr = [arr for arr in arrays if direct[arr.basename] is None]
    digests = {name: hashlib.sha256() for name in first}
    big = np.iinfo(np.int64).max
    lo, hi = np.full((len(starts), 3), big), np.full((len(starts), 3), -big)
    for a in range(0, n, spec.shard_points):
        b = min(a + spec.shard_points, n)
        values = columns(a, b)
        for name, writer in direct.items():
            if writer is not None:
                writer.write_shard(a // spec.shard_points, values[name])
        await asyncio.gather(*(arr.setitem(slice(a, b), values[arr.basename]) for arr in through_zarr))
        for name, v in values.items():
            digests[name].update(np.ascontiguousarray(v).data)  # no copy: the columns are contiguous
        counts = values[COUNTS]  # bounds in counts: dequantising is monotonic, so only theirs
        cut = np.union1d([a], starts[(starts > a) & (starts < b)])
        node = np.searchsorted(starts, cut, side="right") - 1
        lo[node] = np.minimum(lo[node], np.minimum.reduceat(counts, cut - a))
        hi[node] = np.maximum(hi[node], np.maximum.reduceat(counts, cut - a))
    checksum = hashlib.sha256()
    for name, d in digests.items():
        checksum.update(name.encode() + d.digest())
    origin = tile_origin_local(*parse_tile_key(key), spec.tile_size_m)
    return (
        checksum.hexdigest(),
        dequantise(lo, origin, spec.quantum_m),
        dequantise(hi, origin, spec.quantum_m),
    )


def write_tile(
    key: str,
    parts: list[Slice],
    group_path: str,
    spec: TileSpec,
    seed: int,
    scratch: str | None,
    batch_points: int,
) -> WrittenTile:
    """Level, order and write one tile's arrays (``parts``: its slices of the partition, by block) into
    the store ``group_path`` (a local path or an fsspec URL); a tile of more than ``batch_points``
    points goes in batches through ``scratch`` (a local folder; None: a temporary one). Returns its
    key, points, checksum and node rows."""
    import tempfile

    from zarr.core.sync import sync

    seed = tile_seed(key, seed)
    groups = batches(parts, batch_points)
    z0 = min(p.zmin for p in parts)
    with tempfile.TemporaryDirectory(prefix="siteline-tile-", dir=scratch) as work:
        if len(groups) == 1:
            plan, columns, scale = _in_memory(key, parts, spec, seed, z0)
        else:
            placed = Path(scratch) if scratch is not None else Path(work)
            plan, columns, scale = _out_of_core(key, groups, spec, seed, z0, Path(work), placed)
        checksum, lo, hi = sync(_write(group_path, key, plan, columns, spec, scale))
    return WrittenTile(key, plan.points, checksum, plan.table(key, lo, hi))
