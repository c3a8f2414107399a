"""LAS/LAZ -> one Zarr v3 group per scene, tiled on the site grid with an additive level of detail.

Two phases, both spread over worker processes (``workers``):

1. **Partition**: the file's points are cut into ranges; each range is decoded (LAZ: lazrs), brought
   into the site frame (siteline.sitestream), quantised, sorted by tile and appended to the range's
   own run file, one write per chunk with a (tile, offset, count) row per tile it touches. Ranges
   decode in parallel; no Python loop runs over tiles.
2. **Write**: each tile gathers its slices of every run, is levelled (siteline.tiles.lod), ordered
   into nodes (siteline.tiles.nodes) and written as whole arrays with their shards by one worker
   (concurrent partial-shard writes lose data, zarr-python issue 3682).

The node index goes into the group as one set of compact arrays (siteline.tiles.index). The store is
written in place: callers that need all-or-nothing publish it through ``siteline.stores.Store.publish``
(``tiles.execute`` does).
"""

from __future__ import annotations

import hashlib
import shutil
import time
import zlib
from collections.abc import Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
import pyproj

from siteline.crs import ZUnit, crs_text, parse_source_crs
from siteline.errors import TileError
from siteline.lasio import DEFAULT_CHUNK_POINTS, detect_eight_bit, open_las
from siteline.progress import Progress, no_progress
from siteline.records.tiling import NodeTable, TileSpec
from siteline.site import SiteSpec
from siteline.sitestream import SiteChunk, site_chunks, source_transformer
from siteline.stores.owners import owner_tag, sweep_stale
from siteline.tiles.codecs import array_codecs
from siteline.tiles.index import FORMAT_VERSION, write_index
from siteline.tiles.layout import (
    ATTRIBUTES,
    COUNTS,
    SPILL_DTYPE,
    dequantise,
    level_count,
    tile_key,
    tile_origin_local,
)
from siteline.tiles.lod import assign_levels
from siteline.tiles.nodes import order_tile, tile_table

# below this many points one process does everything (a worker's start-up costs about a second)
PARALLEL_MIN_POINTS = 2_000_000
# points per partition range: small enough to report progress and balance the workers
RANGE_POINTS = 4_000_000
_TILE_OFFSET = 1 << 20


@dataclass(frozen=True)
class TileResult:
    """What :func:`write_tiles` wrote: the store (a local path), its points, tiles and levels, bytes on
    disk, checksum (of every array of every tile, in order), the node index, and the seconds it took
    (partitioning and writing apart)."""

    uri: str
    points: int
    tiles: int
    levels: int
    bytes: int
    checksum: str
    nodes: NodeTable
    seconds: float
    partition_seconds: float = 0.0

    @property
    def bytes_per_point(self) -> float:
        return self.bytes / max(self.points, 1)


@dataclass(frozen=True)
class _Source:
    """What a partition worker needs to read the file into the site frame (picklable)."""

    path: str
    site: SiteSpec
    crs: str
    z_unit: dict[str, Any] | None
    spec: dict[str, Any]
    eight_bit: bool | None


@dataclass(frozen=True)
class Run:
    """One partition range's run file: records (``SPILL_DTYPE``) sorted by tile within each chunk,
    and per (chunk, tile) a row of ``tile_id``, ``offset`` (records) and ``count``."""

    path: str
    tile_id: np.ndarray
    offset: np.ndarray
    count: np.ndarray


def _tile_ids(ij: np.ndarray) -> np.ndarray:
    return (ij[:, 0] + _TILE_OFFSET) << 21 | (ij[:, 1] + _TILE_OFFSET)


def _tile_of(tile_id: int) -> tuple[int, int]:
    return (tile_id >> 21) - _TILE_OFFSET, (tile_id & ((1 << 21) - 1)) - _TILE_OFFSET


def _chunk_records(sc: SiteChunk, spec: TileSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A chunk's records sorted by tile (a radix sort of compact tile codes), the ids of the tiles it
    touches and where each one's records start."""
    n = len(sc.local)
    ij = np.floor(sc.local[:, :2] * (1.0 / spec.tile_size_m)).astype(np.int64)
    lo = ij.min(axis=0) if n else np.zeros(2, np.int64)
    span = ij.max(axis=0) - lo + 1 if n else np.ones(2, np.int64)
    code = (ij[:, 0] - lo[0]) * span[1] + (ij[:, 1] - lo[1])
    order = np.argsort(code.astype(np.int16 if span.prod() < 2**15 else np.int64), kind="stable")
    code = code[order]
    first = np.r_[0, np.flatnonzero(code[1:] != code[:-1]) + 1] if n else np.zeros(0, np.int64)
    tij = np.c_[code[first] // span[1] + lo[0], code[first] % span[1] + lo[1]]
    # int32 quanta from each point's tile origin: x, y less the tile corner, z from 0
    q = sc.local.copy()
    q[:, :2] -= ij * spec.tile_size_m
    q *= 1.0 / spec.quantum_m
    np.rint(q, out=q)
    if n and np.abs(q).max() >= 2**31 - 1:
        raise TileError("a coordinate overflows the int32 tile counts; is the tile size right?")
    rec = np.empty(n, SPILL_DTYPE)
    rec[COUNTS] = q.astype(np.int32)[order]
    ch = sc.chunk
    rec["rgb"] = ch.rgb[order] if ch.rgb is not None else 0
    rec["intensity"] = ch.intensity[order]
    rec["class"] = sc.classes[order]
    rec["gps_time"] = ch.gps_time[order] if ch.gps_time is not None else 0.0
    rec["return_number"] = ch.return_number[order]
    return rec, _tile_ids(tij), first


def partition(source: _Source, run_path: str, start: int, stop: int) -> Run:
    """Points [start, stop) of the file into the run file ``run_path`` (runs in a worker process)."""
    spec = TileSpec.from_dict(source.spec)
    path = Path(source.path)
    tr = source_transformer(
        path, source.site, parse_source_crs(source.crs), ZUnit.from_dict(source.z_unit) if source.z_unit else None
    )
    rows: list[np.ndarray] = []
    written = 0
    with open(run_path, "wb") as fh:
        for sc in site_chunks(path, source.site, tr, start=start, stop=stop, eight_bit=source.eight_bit):
            rec, ids, first = _chunk_records(sc, spec)
            rec.tofile(fh)
            rows.append(np.c_[ids, written + first, np.diff(np.r_[first, len(rec)])])
            written += len(rec)
    table = np.concatenate(rows) if rows else np.zeros((0, 3), np.int64)
    return Run(run_path, table[:, 0], table[:, 1], table[:, 2])


def _tile_seed(key: str, seed: int) -> int:
    return zlib.crc32(key.encode()) ^ (seed * 2654435761 & 0xFFFFFFFF)


def _gather(parts: list[tuple[str, int, int]]) -> np.ndarray:
    """A tile's records from its slices (run file, offset, count) of the runs."""
    size = SPILL_DTYPE.itemsize
    out = np.empty(sum(c for _, _, c in parts), SPILL_DTYPE)
    at = 0
    for path, offset, count in parts:
        out[at : at + count] = np.fromfile(path, dtype=SPILL_DTYPE, count=count, offset=offset * size)
        at += count
    return out


async def _write_arrays(group_path: str, key: str, columns: dict[str, np.ndarray], spec: TileSpec) -> None:
    """Create and fill the tile's arrays concurrently (one event loop turn, not one per array)."""
    import asyncio

    from zarr.api.asynchronous import open_group

    root = await open_group(store=group_path, mode="a")
    group = await (await root.require_group("tiles")).create_group(key)

    async def one(name: str, values: np.ndarray) -> None:
        arr = await group.create_array(
            name,
            shape=values.shape,
            dtype=values.dtype,
            chunks=(spec.chunk_points, *values.shape[1:]),
            shards=(spec.shard_points, *values.shape[1:]),
            fill_value=0,
            **array_codecs(name, values.dtype, spec),
        )
        await arr.setitem(slice(None), values)

    await asyncio.gather(*(one(name, values) for name, values in columns.items()))


def write_tile(
    key: str, parts: list[tuple[str, int, int]], group_path: str, spec_doc: dict, seed: int
) -> tuple[str, int, str, NodeTable]:
    """Level, order and write one tile's arrays (runs in a worker process); return its key, points,
    checksum and node rows."""
    from zarr.core.sync import sync

    spec = TileSpec.from_dict(spec_doc)
    rec = _gather(parts)
    counts = rec[COUNTS]
    levels = assign_levels(counts, spec, _tile_seed(key, seed))
    ordered = order_tile(counts, levels, spec, level_count(spec), _tile_seed(key, seed) ^ 0x5EED)
    # one field at a time: a gather of whole records is slower
    columns = {name: rec[name][ordered.order] for name in ATTRIBUTES}
    del rec
    sync(_write_arrays(group_path, key, columns, spec))
    digest = hashlib.sha256()
    for name, values in columns.items():
        digest.update(name.encode())
        digest.update(values.tobytes())
    i, j = (int(v) for v in key[1:].split("_"))
    local = dequantise(columns[COUNTS], tile_origin_local(i, j, spec.tile_size_m), spec.quantum_m)
    return key, len(levels), digest.hexdigest(), tile_table(key, ordered, local)


def _dir_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def _ranges(total: int, workers: int) -> list[tuple[int, int]]:
    """Point ranges of the file: about ``RANGE_POINTS`` each, at least one per worker."""
    pieces = max(workers if total >= PARALLEL_MIN_POINTS else 1, -(-total // RANGE_POINTS), 1)
    size = -(-total // pieces)
    size = -(-size // 50_000) * 50_000  # whole LAZ chunks (laszip's default 50,000 points)
    return [(a, min(a + size, total)) for a in range(0, total, size)] or [(0, 0)]


@contextmanager
def _pool(workers: int, total: int) -> Iterator[Executor | None]:
    """Worker processes when the scene is big enough to pay their start-up, else None (in process).
    spawn: zarr runs an event loop thread that a forked child must not inherit."""
    if workers > 1 and total >= PARALLEL_MIN_POINTS:
        with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
            yield pool
    else:
        with nullcontext() as none:
            yield none


def _map(pool: Executor | None, fn: Any, *iterables: Any) -> Iterator[Any]:
    return pool.map(fn, *iterables) if pool is not None else map(fn, *iterables)


def _parts_by_tile(runs: list[Run]) -> dict[str, list[tuple[str, int, int]]]:
    """Per tile key, its slices (run file, offset, count) in run order."""
    ids = np.concatenate([r.tile_id for r in runs])
    offsets = np.concatenate([r.offset for r in runs])
    counts = np.concatenate([r.count for r in runs])
    which = np.concatenate([np.full(len(r.tile_id), k) for k, r in enumerate(runs)])
    order = np.argsort(ids, kind="stable")
    out: dict[str, list[tuple[str, int, int]]] = {}
    for tid, k, off, c in zip(ids[order].tolist(), which[order].tolist(), offsets[order].tolist(), counts[order].tolist(), strict=True):
        out.setdefault(tile_key(*_tile_of(tid)), []).append((runs[k].path, off, c))
    return out


def _partition_all(
    pool: Executor | None, source: _Source, total: int, workers: int, spill_dir: Path, progress: Progress
) -> list[Run]:
    """Partition the file's ranges into run files under ``spill_dir`` (in parallel with a pool)."""
    ranges = _ranges(total, workers)
    paths = [str(spill_dir / f"run-{k:05d}.bin") for k in range(len(ranges))]
    runs = []
    starts, stops = zip(*ranges, strict=True)
    for (a, b), run in zip(ranges, _map(pool, partition, [source] * len(ranges), paths, starts, stops), strict=True):
        runs.append(run)
        progress("partitioning", b - a, total)
    return runs


def _write_all(
    pool: Executor | None,
    parts: dict[str, list[tuple[str, int, int]]],
    out: Path,
    spec: TileSpec,
    seed: int,
    progress: Progress,
) -> list[tuple[str, int, str, NodeTable]]:
    """Write every tile of ``parts`` into the group ``out`` (in parallel with a pool), in key order."""
    keys = sorted(parts)
    n = len(keys)
    results = []
    for res in _map(pool, write_tile, keys, [parts[k] for k in keys], [str(out)] * n, [spec.to_dict()] * n, [seed] * n):
        results.append(res)
        progress("writing tiles", 1, n)
    return results


def write_tiles(
    las_path: Path,
    site: SiteSpec,
    src_crs: pyproj.CRS,
    out: Path,
    spec: TileSpec | None = None,
    workers: int = 2,
    seed: int = 0,
    progress: Progress = no_progress,
    z_unit: ZUnit | None = None,
    eight_bit: bool | None = None,
) -> TileResult:
    """Tile ``las_path`` into the new Zarr group ``out`` (which must not exist; removed again on an
    error); return its node index. ``z_unit``: the unit of the file's z recorded at ingest (None: the
    unit its CRS implies). ``eight_bit``: whether its colour is 0-255 in 16-bit fields, as ingest
    recorded it (None: judged from its first chunk)."""
    import zarr

    t0 = time.perf_counter()
    spec = spec or TileSpec(tile_size_m=site.tile_size_m)
    out = Path(out)
    if out.exists():
        raise TileError(f"tile store {out} already exists; remove it or tile into another path.")
    source_transformer(las_path, site, src_crs, z_unit)  # refuse an impossible transformation up front
    with open_las(las_path) as reader:
        total = int(reader.header.point_count)
        if eight_bit is None:
            eight_bit = detect_eight_bit(reader, DEFAULT_CHUNK_POINTS)
    if total == 0:
        raise TileError(f"point cloud {las_path} holds no points to tile.")
    out.parent.mkdir(parents=True, exist_ok=True)
    sweep_stale(out.parent, ".*.spill-*")
    spill_dir = out.with_name(f".{out.name}.spill-{owner_tag()}")
    spill_dir.mkdir(parents=True)
    source = _Source(
        str(las_path), site, crs_text(src_crs), z_unit.to_dict() if z_unit else None, spec.to_dict(), eight_bit
    )
    try:
        with _pool(workers, total) as pool:
            runs = _partition_all(pool, source, total, workers, spill_dir, progress)
            t_part = time.perf_counter() - t0
            parts = _parts_by_tile(runs)
            if not parts:
                raise TileError(f"point cloud {las_path} holds no points to tile.")
            root = zarr.open_group(str(out), mode="w")
            root.create_group("tiles")
            results = _write_all(pool, parts, out, spec, seed, progress)
        nodes = NodeTable.concat([r[3] for r in results])
        checksum = hashlib.sha256("\n".join(f"{k}:{c}" for k, _, c, _ in results).encode()).hexdigest()
        points = sum(r[1] for r in results)
        write_index(root, nodes)
        root.attrs.update(
            {"siteline_tiles": FORMAT_VERSION, "spec": spec.to_dict(), "site_origin": list(site.origin),
             "crs": site.crs, "points": points, "checksum": checksum}
        )  # fmt: skip
        size = _dir_bytes(out)
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        raise
    finally:
        shutil.rmtree(spill_dir, ignore_errors=True)
    return TileResult(
        str(out), points, len(results), nodes.levels, size, checksum, nodes, time.perf_counter() - t0, t_part
    )
