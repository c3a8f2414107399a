"""How a scene's tiles are read with one of its label-set versions, and how a version's classes are
written.

Version 1 is the classification the tile store was written with. Every later version is a Zarr group
(``siteline.stores.layout.label_set``) holding ``tiles/<tile>/class`` (uint8 site class ids) for every
tile, aligned point for point with the tile store's arrays (level order), so a reader reads it as the
``class`` attribute and reads classes exactly as before.
"""

from __future__ import annotations

import numpy as np
import zarr

from siteline.errors import LabelSetError
from siteline.records.labelsets import LabelSetRef
from siteline.records.tiling import TileSource, TileSpec
from siteline.tiles.reader import SceneTiles

FORMAT_VERSION = 1


def open_labelled(source: TileSource, label_set: LabelSetRef) -> SceneTiles:
    """The scene's tiles reading the classes of ``label_set``. LabelSetError when that version was
    written for another tiling of the scene (the scene was tiled again since: its points are in
    another order)."""
    tiles = SceneTiles.from_source(source)
    if label_set.uri is None:
        return tiles
    tiles = tiles.with_attribute("class", label_set.uri)
    made_for = tiles.attribute_record("class").get("tile_checksum")
    if made_for is not None and made_for != source.checksum:
        raise LabelSetError(
            f"label set {label_set.version} of scene {label_set.scene_id} was written for another tiling of "
            f"the scene (the scene was tiled again since): import its file again ({label_set.source}, "
            f"sha256 {label_set.source_sha256})."
        )
    return tiles


def write_tile_classes(group: zarr.Group, tile: str, classes: np.ndarray, spec: TileSpec) -> None:
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
