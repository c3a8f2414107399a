"""The Zarr v3 tile store: site-grid tiles with an additive level of detail (DESIGN.md §2, §7).

The tile stage: :func:`plan_tiling` (catalog) -> :func:`execute_tiling` (write and publish the
store) -> ``siteline.catalog.scenes.record_tiling``; :func:`tile_scene` runs the three."""

from siteline.records.tiling import NodeTable, SceneTiling, TileSource, TileSpec
from siteline.tiles.execute import execute_tiling
from siteline.tiles.export import export_las
from siteline.tiles.lod import assign_levels
from siteline.tiles.plan import TilingPlan, plan_tiling
from siteline.tiles.reader import Points, ReadStats, SceneTiles
from siteline.tiles.stage import TileOutcome, tile_scene
from siteline.tiles.writer import TileResult, write_tiles

__all__ = [
    "NodeTable",
    "Points",
    "ReadStats",
    "SceneTiles",
    "SceneTiling",
    "TileOutcome",
    "TileResult",
    "TileSource",
    "TileSpec",
    "TilingPlan",
    "assign_levels",
    "execute_tiling",
    "export_las",
    "plan_tiling",
    "tile_scene",
    "write_tiles",
]
