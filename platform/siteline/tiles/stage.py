"""The tile stage: plan (catalog) -> execute (write the store) -> record (catalog)."""

from __future__ import annotations

import logging
from dataclasses import dataclass

from siteline.catalog.context import StageContext
from siteline.catalog.scenes import record_tiling
from siteline.pointpass import PartitionCache, TilingResources
from siteline.records.runs import StageRun
from siteline.records.tiling import SceneTiling, TileSpec
from siteline.stores import layout
from siteline.tiles.execute import execute_tiling
from siteline.tiles.plan import plan_tiling
from siteline.tiles.reader import SceneTiles, class_counts

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TileOutcome:
    """What ``tile_scene`` did: the tiling it recorded (None when there was nothing to do) and one
    sentence saying so."""

    tiling: SceneTiling | None
    message: str


def tile_scene(
    ctx: StageContext,
    scene_id: int,
    *,
    spec: TileSpec | None = None,
    resources: TilingResources = TilingResources(),
    retile: bool = False,
) -> TileOutcome:
    """Tile a registered scene and index its nodes; a scene already tiled is left alone unless
    ``retile`` (tile it again in the current layout, e.g. a store written in input order) or its
    tiling is of an earlier site version (``site update --taxonomy/--fence``): then its classes are
    mapped again, and label set 1's class histogram follows.

    The store (its node index inside) is published whole before its address and the scene's status
    are committed; a store without rows (a crash between the two) is replaced. A re-tiling writes the
    next generation beside the old store, commits, then removes the old one: the scene's pairs'
    outputs are keyed by the generation, and its imported label sets, aligned with the old order,
    are refused until imported again (siteline.labelsets). One tiling of a scene runs at a time (a
    second caller waits, then finds the scene tiled). ``resources``: workers or an executor (a Dask
    cluster's, whose workers share the store) and the batch budget (None: the settings'); the
    partition ingest kept is looked for in the home."""
    with ctx.catalog.lock(f"scene:{scene_id}:tiles"):
        return _tile(ctx, scene_id, spec, resources, retile)


def _tile(
    ctx: StageContext, scene_id: int, spec: TileSpec | None, resources: TilingResources, retile: bool,
) -> TileOutcome:  # fmt: skip
    with ctx.catalog.transaction() as s:
        plan = plan_tiling(s, scene_id)
    store = ctx.settings.store
    done = plan.tiled and plan.current is not None and store.is_complete(plan.current.uri)
    if done and not retile and not plan.stale:
        log.info("scene %d is already tiled", scene_id)
        return TileOutcome(None, plan.already_tiled())
    spec = spec or TileSpec.for_site(plan.site)
    run = StageRun(
        "tile", f"scene:{scene_id}", {"spec": spec.to_dict(), "workers": resources.workers}, run_id=ctx.run_id
    )
    cache = PartitionCache(layout.partitions(ctx.settings.home))
    cache.sweep_unfinished()  # a partition an ingest killed after its commit was writing
    resources = resources.completed(batch_points=ctx.settings.tile_batch_points, partitions=cache)
    tiling = execute_tiling(plan, store, spec, plan.generation(done), resources, ctx.progress)
    try:
        counts = class_counts(SceneTiles.open(tiling.uri)) if done else None
        with ctx.catalog.transaction() as s:
            record_tiling(s, scene_id, tiling, run, counts)
    except BaseException:
        store.remove(tiling.uri)
        raise
    old = plan.current.uri if done and plan.current is not None else None
    if old is not None and old != tiling.uri:
        store.remove(old)
    verb = "re-tiled" if old else "tiled"
    return TileOutcome(
        tiling,
        f"scene {scene_id} {verb}: {tiling.points:,} points in {tiling.tiles} tiles, {tiling.levels} levels, "
        f"{tiling.nodes:,} nodes, {tiling.bytes_per_point:.1f} bytes/point "
        f"(the source file: {tiling.source_bytes_per_point:.1f})",
    )
