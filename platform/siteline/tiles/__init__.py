"""The Zarr v3 tile store: site-grid tiles with an additive level of detail (DESIGN.md §2, §7)."""

from siteline.tiles.export import export_las
from siteline.tiles.layout import TileSpec
from siteline.tiles.lod import assign_levels
from siteline.tiles.reader import SceneTiles
from siteline.tiles.scene import open_scene_tiles, store_uri, tile_scene
from siteline.tiles.writer import NodeInfo, TileResult, write_tiles

__all__ = [
    "NodeInfo",
    "SceneTiles",
    "TileResult",
    "TileSpec",
    "assign_levels",
    "export_las",
    "open_scene_tiles",
    "store_uri",
    "tile_scene",
    "write_tiles",
]
