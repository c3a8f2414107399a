"""The Zarr v3 tile store: site-grid tiles with an additive level of detail (DESIGN.md §2, §7).

The tile stage: :func:`plan_tiling` (catalog) -> :func:`execute_tiling` (write and publish the
store) -> ``siteline.catalog.scenes.record_tiling``; :func:`tile_scene` runs the three."""

from __future__ import annotations

from siteline.lazy import lazy_names

# imported on first use: a worker process that writes tiles needs none of the stage's catalog
_WHERE = {
    "NodeTable": "siteline.records.tiling",
    "SceneTiling": "siteline.records.tiling",
    "TileSource": "siteline.records.tiling",
    "TileSpec": "siteline.records.tiling",
    "execute_tiling": "siteline.tiles.execute",
    "export_las": "siteline.tiles.export",
    "assign_levels": "siteline.tiles.lod",
    "TilingPlan": "siteline.tiles.plan",
    "plan_tiling": "siteline.tiles.plan",
    "Points": "siteline.tiles.reader",
    "ReadStats": "siteline.tiles.reader",
    "SceneTiles": "siteline.tiles.reader",
    "TileOutcome": "siteline.tiles.stage",
    "tile_scene": "siteline.tiles.stage",
    "TileResult": "siteline.tiles.writer",
    "write_tiles": "siteline.tiles.writer",
}
__all__ = sorted(_WHERE)


__getattr__ = lazy_names(__name__, _WHERE)
