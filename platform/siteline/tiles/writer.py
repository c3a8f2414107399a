"""LAS/LAZ -> one Zarr v3 group per scene, tiled on the site grid with an additive level of detail.

Two phases, both spread over worker processes (``workers``):

1. **Partition** (siteline.pointpass.partition): the file's points cut into tile runs in parallel ranges. Ingest
   keeps the partition its scan made (the same pass), so tiling right after ingest skips this phase;
   otherwise it runs here.
2. **Write**: each tile gathers its slices of every run, is levelled (siteline.pointpass.lod), ordered
   into nodes (siteline.pointpass.nodes) and written shard by shard by one worker, a batch of its
   blocks at a time when it is large (siteline.tiles.batches; concurrent partial-shard writes lose
   data, zarr-python issue 3682).

The node index goes into the group as one set of compact arrays (siteline.tiles.index). The store is
written in place: callers that need all-or-nothing publish it through ``siteline.stores.Store.publish``
(``tiles.execute`` does).
"""

from __future__ import annotations

import hashlib
import logging
import shutil
import tempfile
import time
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyproj

from siteline.errors import TileError
from siteline.pointpass import (
    PARALLEL_MIN_POINTS,
    Correction,
    Partition,
    PassSource,
    Slice,
    TilingResources,
    detect_eight_bit,
    open_las,
    pass_file,
    pool_map,
    process_pool,
    source_transformer,
)
from siteline.progress import Progress, no_progress
from siteline.records.tiling import NodeTable, TileSpec
from siteline.site.crs import ZUnit, crs_text, z_unit_of
from siteline.site.spec import SiteSpec
from siteline.stores import Store, open_store
from siteline.stores.owners import owner_tag, sweep_stale
from siteline.tiles.batches import BATCH_POINTS, WrittenTile, write_tile
from siteline.tiles.index import FORMAT_VERSION, write_index
from siteline.tiles.layout import tile_key

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TileResult:
    """What :func:`write_tiles` wrote: the store (a local path or an fsspec URL), its points, tiles and levels, bytes on
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


def _share_runs(
    store: Store, parts: dict[str, list[Slice]], folder: Path, uri: str
) -> dict[str, list[Slice]]:
    """Copy the partition's run files to ``uri`` (where a cluster's workers read them); the same
    slices of the copies."""
    names = sorted({Path(p.path).name for slices in parts.values() for p in slices})
    for n in names:
        store.put_file(folder / n, f"{uri}/{n}")
    return {k: [p._replace(path=f"{uri}/{Path(p.path).name}") for p in v] for k, v in parts.items()}


def _partition(
    source: PassSource, total: int, spec: TileSpec, folder: Path, workers: int, progress: Progress
) -> Partition:
    """Cut the file into tile runs in ``folder`` (in parallel ranges with a pool)."""
    done = pass_file(
        source, total, workers, runs_into=folder, spec=spec, progress=progress, label="partitioning"
    )
    return done.partition if done.partition is not None else Partition(folder, ())


def _write_all(
    pool: Executor | None,
    parts: dict[str, list[Slice]],
    out: str,
    spec: TileSpec,
    seed: int,
    scratch: str | None,
    batch_points: int,
    progress: Progress,
) -> list[WrittenTile]:
    """Write every tile of ``parts`` into the group ``out`` (in parallel with a pool), in key order;
    ``scratch``: the workers' folder for large tiles (None: each makes its own)."""
    keys = sorted(parts)
    n = len(keys)
    results = []
    for res in pool_map(
        pool, write_tile, keys, [parts[k] for k in keys], [str(out)] * n, [spec] * n, [seed] * n,
        [scratch] * n, [batch_points] * n,
    ):  # fmt: skip
        results.append(res)
        progress("writing tiles", 1, n)
    return results


@dataclass(frozen=True)
class TileInput:
    """The point cloud to tile and what ingest recorded of it: the file, the site, the file's CRS,
    the unit of its z (None: the unit the CRS implies), whether its colour is 0-255 in 16-bit fields
    (None: judged from its first chunk), the scene's co-registration (applied to every point as it is
    cut, siteline.pointpass.sitestream.site_chunks), and the file's sha256 (with
    :attr:`TilingResources.partitions`: the partition ingest kept of it is used when it matches)."""

    path: Path
    site: SiteSpec
    crs: pyproj.CRS
    z_unit: ZUnit | None = None
    eight_bit: bool | None = None
    correction: Correction | None = None
    sha256: str | None = None


def write_tiles(
    source: TileInput,
    out: Path | str,
    spec: TileSpec | None = None,
    resources: TilingResources = TilingResources(),
    seed: int = 0,
    progress: Progress = no_progress,
) -> TileResult:
    """Tile ``source`` into the new Zarr group ``out`` (a local path or an fsspec URL; it must not
    exist; removed again on an error) with ``resources`` (workers or an executor, batch budget,
    scratch folder, kept partitions: :class:`TilingResources`); return its node index. With an
    executor the partition's runs are copied beside ``out``, where its workers read them."""
    import zarr

    t0 = time.perf_counter()
    spec = spec or TileSpec.for_site(source.site)
    target, store = str(out), open_store(str(out))
    total, eight_bit = _check_source(source, store, target)
    spill_dir = _spill_dir(target, resources.scratch)
    executor, workers = resources.executor, resources.workers
    # the caller's executor (a cluster's) reads the runs beside the store; this machine's pool, here
    runs_uri = f"{target.rstrip('/')}.runs-{owner_tag()}" if executor is not None else None
    las = source.path
    passing = PassSource(
        str(las), source.site, crs_text(source.crs), z_unit_of(source.crs, source.z_unit), eight_bit,
        source.correction,
    )  # fmt: skip
    try:
        partition = None
        if resources.partitions is not None and source.sha256 is not None:
            partition = resources.partitions.claim(passing, source.sha256, spec, spill_dir)
        if partition is None:
            spill_dir.mkdir(parents=True)
            partition = _partition(passing, total, spec, spill_dir, workers, progress)
        else:
            log.info("tiling %s from the partition its ingest kept", las.name)
        t_part = time.perf_counter() - t0
        parts = {tile_key(*ij): p for ij, p in partition.parts_by_tile().items()}
        if runs_uri is not None:
            parts = _share_runs(store, parts, spill_dir, runs_uri)
        root = zarr.open_group(target, mode="w")
        root.create_group("tiles")
        if executor is None and workers > 1 and total >= PARALLEL_MIN_POINTS:
            executor = process_pool(workers)
        how = type(executor).__name__ if executor is not None else "this process"
        log.info("writing %d tiles of %s with %s", len(parts), las.name, how)
        worker_scratch = None if runs_uri is not None else str(spill_dir)
        batch = resources.batch_points or BATCH_POINTS
        results = _write_all(executor, parts, target, spec, seed, worker_scratch, batch, progress)
        nodes, checksum = _index(root, results, total, las, spec, source.site)
        size = store.size(target)
    except BaseException:
        store.remove(target)
        raise
    finally:
        shutil.rmtree(spill_dir, ignore_errors=True)
        if runs_uri is not None:
            store.remove(runs_uri)
    return TileResult(
        target,
        nodes.points,
        len(results),
        nodes.levels,
        size,
        checksum,
        nodes,
        time.perf_counter() - t0,
        t_part,
    )


def _check_source(source: TileInput, store: Store, target: str) -> tuple[int, bool | None]:
    """The file's point count and colour depth, after refusing an existing ``target``, an impossible
    transformation or an empty file."""
    if store.exists(target):
        raise TileError(f"tile store {target} already exists; remove it or tile into another path.")
    las, eight_bit = source.path, source.eight_bit
    source_transformer(las, source.site, source.crs, source.z_unit)
    with open_las(las) as reader:
        total = int(reader.header.point_count)
        if eight_bit is None:
            eight_bit = detect_eight_bit(reader, las)
    if total == 0:
        raise TileError(f"point cloud {las} holds no points to tile.")
    return total, eight_bit


def _spill_dir(target: str, scratch: Path | None) -> Path:
    """A fresh name for the partition of a tiling of ``target``, in the local folder ``scratch``
    (default: the system's temporary folder); stale ones there are swept."""
    folder = Path(scratch) if scratch is not None else Path(tempfile.gettempdir())
    folder.mkdir(parents=True, exist_ok=True)
    sweep_stale(folder, ".*.spill-*")
    return folder / f".{target.rstrip('/').rsplit('/', 1)[-1]}.spill-{owner_tag()}"


def _index(
    root: Any, results: list[WrittenTile], total: int, las_path: Path, spec: TileSpec, site: SiteSpec
) -> tuple[NodeTable, str]:
    """Write the store's node index and attributes; return the index and the store's checksum."""
    nodes = NodeTable.concat([r.nodes for r in results])
    checksum = hashlib.sha256("\n".join(f"{r.key}:{r.checksum}" for r in results).encode()).hexdigest()
    if nodes.points != total or sum(r.points for r in results) != total:
        raise TileError(
            f"point cloud {las_path}: its header counts {total:,} points but {nodes.points:,} were tiled."
        )
    write_index(root, nodes)
    root.attrs.update(
        {"siteline_tiles": FORMAT_VERSION, "spec": spec.to_dict(), "site_origin": list(site.origin),
         "crs": site.crs, "points": total, "checksum": checksum}
    )  # fmt: skip
    return nodes, checksum
