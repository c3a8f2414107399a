"""LAS/LAZ -> one Zarr v3 group per scene, tiled on the site grid with an additive level of detail.

Memory stays bounded: one streaming pass spills every chunk's points into per-tile files (an external
partition), then each tile is loaded alone, levelled, sorted by level and written. Workers each own
whole tiles, i.e. whole arrays and their shards (concurrent partial-shard writes lose data, zarr-python
issue 3682). The store is written in place: callers that need all-or-nothing publish it through
``siteline.stores.Store.publish`` (``tiles.scene.tile_scene`` does).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import time
import zlib
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
import pyproj
from zarr.codecs import BloscCodec, BloscShuffle

from siteline.crs import ToSiteCRS, ZUnit
from siteline.errors import TileError
from siteline.progress import Progress, no_progress, step
from siteline.records.tiling import NodeInfo, TileSpec
from siteline.site import SiteSpec
from siteline.sitestream import site_chunks, source_transformer
from siteline.stores.owners import owner_tag, sweep_stale
from siteline.tiles.layout import (
    ATTRIBUTES,
    COUNTS,
    SPILL_DTYPE,
    dequantise,
    node_cells,
    node_key,
    parse_tile_key,
    quantise,
    tile_index,
    tile_key,
    tile_origin_local,
)
from siteline.tiles.lod import assign_levels

FORMAT_VERSION = 1
PARALLEL_MIN_POINTS = 2_000_000


@dataclass(frozen=True)
class TileResult:
    """What :func:`write_tiles` wrote: the store (a local path), its points, tiles and levels, bytes on
    disk, checksum (of every array of every tile, in order), the nodes, and the seconds it took."""

    uri: str
    points: int
    tiles: int
    levels: int
    bytes: int
    checksum: str
    nodes: tuple[NodeInfo, ...]
    seconds: float

    @property
    def bytes_per_point(self) -> float:
        return self.bytes / max(self.points, 1)


def _codec(spec: TileSpec) -> BloscCodec:

    return BloscCodec(cname="zstd", clevel=spec.clevel, shuffle=BloscShuffle.shuffle)


def _spill(
    las_path: Path,
    site: SiteSpec,
    tr: ToSiteCRS | None,
    spec: TileSpec,
    spill_dir: Path,
    progress: Callable[[int], None],
) -> dict[str, int]:
    """Partition the cloud into per-tile spill files; return the point count per tile."""
    counts: dict[str, int] = {}
    for sc in site_chunks(las_path, site, tr):
        ij = tile_index(sc.local, spec.tile_size_m)
        order = np.lexsort((ij[:, 1], ij[:, 0]))
        ij_sorted = ij[order]
        cuts = np.flatnonzero(np.any(np.diff(ij_sorted, axis=0) != 0, axis=1)) + 1
        ch = sc.chunk
        n = len(sc.local)
        rgb = ch.rgb if ch.rgb is not None else np.zeros((n, 3), np.uint8)
        gps = ch.gps_time if ch.gps_time is not None else np.zeros(n)
        for part in np.split(order, cuts):
            i, j = (int(v) for v in ij[part[0]])
            key = tile_key(i, j)
            rec = np.empty(len(part), SPILL_DTYPE)
            rec[COUNTS] = quantise(sc.local[part], tile_origin_local(i, j, spec.tile_size_m), spec.quantum_m)
            rec["rgb"] = rgb[part]
            rec["intensity"] = ch.intensity[part]
            rec["class"] = sc.classes[part]
            rec["gps_time"] = gps[part]
            rec["return_number"] = ch.return_number[part]
            with open(spill_dir / f"{key}.bin", "ab") as fh:
                rec.tofile(fh)
            counts[key] = counts.get(key, 0) + len(part)
        progress(n)
    return counts


def _tile_seed(key: str, seed: int) -> int:
    return zlib.crc32(key.encode()) ^ (seed * 2654435761 & 0xFFFFFFFF)


def write_tile(key: str, spill_path: str, group_path: str, spec_doc: dict, seed: int) -> dict:
    """Level, sort and write one tile's arrays (runs in a worker process); returns its nodes and checksum."""
    import zarr

    spec = TileSpec.from_dict(spec_doc)
    rec = np.fromfile(spill_path, dtype=SPILL_DTYPE)
    levels = assign_levels(rec[COUNTS], spec, _tile_seed(key, seed))
    cells = node_cells(rec[COUNTS], levels, spec)
    keys: tuple[np.ndarray, ...] = (cells[:, 2], cells[:, 1], cells[:, 0], levels)
    if spec.node_order == "random":  # inside a node, a seeded shuffle: any prefix is a uniform subsample
        keys = (np.random.default_rng(_tile_seed(key, seed) ^ 0x5EED).permutation(len(rec)), *keys)
    order = np.lexsort(keys)
    rec, levels, cells = rec[order], levels[order], cells[order]
    n = len(rec)
    group = zarr.open_group(group_path, mode="a").require_group("tiles").create_group(key)
    digest = hashlib.sha256()
    codec = _codec(spec)
    for name in ATTRIBUTES:
        values = np.ascontiguousarray(rec[name])
        shape = values.shape
        chunks = (spec.chunk_points, *shape[1:])
        shards = (spec.shard_points, *shape[1:])
        arr = group.create_array(
            name,
            shape=shape,
            dtype=values.dtype,
            chunks=chunks,
            shards=shards,
            compressors=codec,
            fill_value=0,
        )
        arr[...] = values
        digest.update(name.encode())
        digest.update(values.tobytes())
    i, j = parse_tile_key(key)
    origin = tile_origin_local(i, j, spec.tile_size_m)
    local = dequantise(rec[COUNTS], origin, spec.quantum_m)
    new = np.ones(n, dtype=bool)
    if n > 1:
        new[1:] = (levels[1:] != levels[:-1]) | np.any(cells[1:] != cells[:-1], axis=1)
    starts = np.flatnonzero(new)
    ends = np.r_[starts[1:], n]
    lo = np.minimum.reduceat(local, starts, axis=0)
    hi = np.maximum.reduceat(local, starts, axis=0)
    nodes = []
    for k, (s, e) in enumerate(zip(starts.tolist(), ends.tolist(), strict=True)):
        level = int(levels[s])
        cell = (int(cells[s][0]), int(cells[s][1]), int(cells[s][2]))
        nodes.append(
            NodeInfo(
                node_key(key, level, cell),
                key,
                level,
                (float(lo[k][0]), float(lo[k][1]), float(lo[k][2])),
                (float(hi[k][0]), float(hi[k][1]), float(hi[k][2])),
                e - s,
                s,
                spec.spacing(level),
                cell,
            ).to_dict()
        )
    os.unlink(spill_path)
    return {"key": key, "points": n, "checksum": digest.hexdigest(), "nodes": nodes}


def _dir_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def _write_all(
    args: list[tuple[str, str, str, dict[str, Any], int]], workers: int, total_points: int, progress: Progress
) -> list[dict[str, Any]]:
    """Run :func:`write_tile` for every tile, in worker processes when it pays off."""
    results = []
    # worker start-up (~1 s: imports) only pays off on big scenes
    if workers > 1 and len(args) > 1 and total_points >= PARALLEL_MIN_POINTS:
        # spawn: zarr runs an event loop thread that a forked child must not inherit
        with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
            for res in pool.map(write_tile, *zip(*args, strict=True)):
                results.append(res)
                progress("writing tiles", 1, len(args))
    else:
        for a in args:
            results.append(write_tile(*a))
            progress("writing tiles", 1, len(args))
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
) -> TileResult:
    """Tile ``las_path`` into the new Zarr group ``out`` (which must not exist; removed again on an
    error); return its nodes. ``z_unit``: the unit of the file's z recorded at ingest (None: the unit
    its CRS implies)."""
    import zarr

    t0 = time.perf_counter()
    spec = spec or TileSpec(tile_size_m=site.tile_size_m)
    out = Path(out)
    if out.exists():
        raise TileError(f"tile store {out} already exists; remove it or tile into another path.")
    out.parent.mkdir(parents=True, exist_ok=True)
    sweep_stale(out.parent, ".*.spill-*")
    spill_dir = out.with_name(f".{out.name}.spill-{owner_tag()}")
    spill_dir.mkdir(parents=True)
    try:
        tr = source_transformer(las_path, site, src_crs, z_unit)
        counts = _spill(las_path, site, tr, spec, spill_dir, step(progress, "partitioning"))
        if not counts:
            raise TileError(f"point cloud {las_path} holds no points to tile.")
        root = zarr.open_group(str(out), mode="w")
        root.create_group("tiles")
        args = [(k, str(spill_dir / f"{k}.bin"), str(out), spec.to_dict(), seed) for k in sorted(counts)]
        results = _write_all(args, workers, sum(counts.values()), progress)
        nodes = tuple(NodeInfo.from_dict(n) for r in results for n in r["nodes"])
        checksum = hashlib.sha256(
            "\n".join(f"{r['key']}:{r['checksum']}" for r in sorted(results, key=lambda r: r["key"])).encode()
        ).hexdigest()
        points = sum(r["points"] for r in results)
        root.attrs.update(
            {"siteline_tiles": FORMAT_VERSION, "spec": spec.to_dict(), "site_origin": list(site.origin),
             "crs": site.crs, "points": points, "checksum": checksum, "nodes": [n.to_dict() for n in nodes]}
        )  # fmt: skip
        size = _dir_bytes(out)
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        raise
    finally:
        shutil.rmtree(spill_dir, ignore_errors=True)
    levels = max(n.level for n in nodes) + 1
    return TileResult(str(out), points, len(args), levels, size, checksum, nodes, time.perf_counter() - t0)
