"""The Zarr v3 tile store: site-grid tiles with an additive level of detail (DESIGN.md §2, §7).

The tile stage: :func:`plan_tiling` (catalog) -> :func:`execute_tiling` (write and publish the
store) -> ``siteline.catalog.scenes.record_tiling``; :func:`tile_scene` runs the three."""

from __future__ import annotations

from typing import TYPE_CHECKING

from siteline.lazy import lazy_names

if TYPE_CHECKING:  # mypy and editors see the real signatures; nothing is imported at run time
    from siteline.records.tiling import NodeTable as NodeTable
    from siteline.records.tiling import SceneTiling as SceneTiling
    from siteline.records.tiling import TileSource as TileSource
    from siteline.records.tiling import TileSpec as TileSpec
    from siteline.tiles.execute import execute_tiling as execute_tiling
    from siteline.tiles.export import export_las as export_las
    from siteline.tiles.lod import assign_levels as assign_levels
    from siteline.tiles.plan import TilingPlan as TilingPlan
    from siteline.tiles.plan import plan_tiling as plan_tiling
    from siteline.tiles.reader import Points as Points
    from siteline.tiles.reader import ReadStats as ReadStats
    from siteline.tiles.reader import SceneTiles as SceneTiles
    from siteline.tiles.stage import TileOutcome as TileOutcome
    from siteline.tiles.stage import tile_scene as tile_scene
    from siteline.tiles.writer import TileInput as TileInput
    from siteline.tiles.writer import TileResult as TileResult
    from siteline.tiles.writer import write_tiles as write_tiles

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
    "TileInput": "siteline.tiles.writer",
    "TileResult": "siteline.tiles.writer",
    "write_tiles": "siteline.tiles.writer",
}
__all__ = sorted(_WHERE)


__getattr__ = lazy_names(__name__, _WHERE)
