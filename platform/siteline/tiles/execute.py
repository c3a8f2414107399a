"""Writing a scene's tile store from its plan: the point cloud found (or fetched from the store),
tiled, and published whole under the store's layout. Never touches the catalog."""

from __future__ import annotations

import logging
from pathlib import Path

from siteline.errors import TileError
from siteline.pointpass import TilingResources
from siteline.progress import Progress, no_progress
from siteline.records.tiling import SceneTiling, TileSpec
from siteline.site.crs import parse_source_crs
from siteline.stores import Store, layout
from siteline.stores.blobs import resolve_file
from siteline.tiles.plan import TilingPlan
from siteline.tiles.writer import TileInput, write_tiles

log = logging.getLogger(__name__)


def scene_las(store: Store, plan: TilingPlan) -> Path:
    """A local path holding the scene's LAS/LAZ bytes (the store's blob, or the referenced original)."""
    las = plan.las
    path = resolve_file(store, las.storage, las.root_uri, las.path, las.sha256)
    if not path.is_file():
        where = (
            "the store"
            if las.storage == "copy"
            else "its mission folder (a referenced mission must stay on a path every worker sees)"
        )
        raise TileError(f"scene {plan.scene_id}: point cloud {path} is missing from {where}.")
    return path


def execute_tiling(
    plan: TilingPlan,
    store: Store,
    spec: TileSpec,
    generation: int,
    resources: TilingResources = TilingResources(),
    progress: Progress = no_progress,
) -> SceneTiling:
    """Tile the scene of ``plan`` into the store at its ``generation``'s address, published whole (a
    store left there without its marker is replaced), its node index inside; return the tiling.
    ``resources``: :class:`siteline.pointpass.TilingResources` (a partition ingest kept in its
    ``partitions`` is used when it matches; with an ``executor``, a Dask cluster's, the tiles are
    written straight into the store, which its workers share)."""
    las = scene_las(store, plan)
    src = parse_source_crs(plan.source_crs) if plan.source_crs else plan.site.pyproj_crs
    uri = layout.tile_store(store, plan.scene_id, generation)
    store.remove(uri)
    log.info("tiling scene %d from %s into %s (generation %d)", plan.scene_id, las.name, uri, generation)
    building = store.publish_shared(uri) if resources.executor is not None else store.publish(uri)
    source = TileInput(las, plan.site, src, plan.z_unit, plan.eight_bit, plan.correction, plan.las.sha256)
    with building as work:
        written = write_tiles(
            source, work, spec, resources.completed(scratch=store.staging), plan.seed, progress
        )
    tiling = SceneTiling(
        uri, spec, written.checksum, generation, written.points, written.tiles, written.levels,
        written.bytes, written.seconds, len(written.nodes), las.stat().st_size, plan.site.version,
    )  # fmt: skip
    log.info(
        "tiled scene %d: %s points in %d tiles, %d levels, %d nodes, %.1f bytes/point (source %.1f), "
        "%.1f s (%.1f s partitioning)",
        plan.scene_id, f"{tiling.points:,}", tiling.tiles, tiling.levels, tiling.nodes,
        tiling.bytes_per_point, tiling.source_bytes_per_point, tiling.seconds, written.partition_seconds,
    )  # fmt: skip
    return tiling
