"""Where label-set versions live and how a scene's tiles are read with one of them.

Version 1 is the classification the tile store was written with. Every later version is a Zarr group
``<store>/labelsets/scene-<id>/v<version>.zarr`` holding ``tiles/<tile>/class`` (uint8 site class ids)
for every tile, aligned point for point with the tile store's arrays (level order), so a reader
attaches it as the ``class`` attribute and reads classes exactly as before.
"""

from __future__ import annotations

import numpy as np
from sqlalchemy.orm import Session

from siteline.catalog.labelsets import label_set
from siteline.catalog.models import Scene
from siteline.config import Settings
from siteline.errors import LabelSetError
from siteline.tiles import open_scene_tiles
from siteline.tiles.layout import TileSpec
from siteline.tiles.reader import SceneTiles
from siteline.tiles.scene import tile_checksum

FORMAT_VERSION = 1


def labelset_uri(settings: Settings, scene_id: int, version: int) -> str:
    return settings.store.uri("labelsets", f"scene-{scene_id}", f"v{version}.zarr")


def open_labelled_tiles(session: Session, scene: Scene, version: int | None = None) -> tuple[SceneTiles, int]:
    """The scene's tiles reading the classes of label-set ``version`` (None: the newest), and that
    version. LabelSetError when that version was written for another tiling of the scene (the scene
    was tiled again since: its points are in another order)."""
    row = label_set(session, scene.id, version)
    tiles = open_scene_tiles(session, scene)
    if row.uri is not None:
        tiles.attach("class", row.uri)
        made_for = tiles.extra["class"].attrs.get("tile_checksum")
        if made_for is not None and made_for != tile_checksum(scene):
            raise LabelSetError(
                f"label set {row.version} of scene {scene.id} was written for another tiling of the scene "
                f"(the scene was tiled again since): import its file again ({row.source}, sha256 "
                f"{row.source_sha256})."
            )
    return tiles, row.version


def tile_classes(tiles: SceneTiles, tile: str) -> np.ndarray:
    """Every point's class of ``tile`` (level order) under the attached label set."""
    return tiles.read({tile: tiles.prefix(tile)}, ("class",))["class"]


def write_tile_classes(group, tile: str, classes: np.ndarray, spec: TileSpec) -> None:  # noqa: ANN001
    """Write ``tiles/<tile>/class`` of a label-set store under construction (the Zarr group ``group``)."""
    from zarr.codecs import BloscCodec, BloscShuffle

    arr = (
        group.require_group("tiles")
        .create_group(tile)
        .create_array(
            "class",
            shape=classes.shape,
            dtype="uint8",
            chunks=(spec.chunk_points,),
            shards=(spec.shard_points,),
            compressors=BloscCodec(cname="zstd", clevel=spec.clevel, shuffle=BloscShuffle.bitshuffle),
            fill_value=0,
        )
    )
    arr[...] = classes
