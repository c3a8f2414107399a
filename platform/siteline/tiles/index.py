"""A tile store's node index: one compact array per column under ``nodes/`` in the store's Zarr group
and the tile keys in its attributes (format 2). Stores of format 1 kept the node list as JSON in the
root attributes; :func:`read_index` still reads them."""

from __future__ import annotations

import numpy as np
import zarr
from zarr.codecs import BloscCodec, BloscShuffle

from siteline.errors import TileError
from siteline.records.tiling import NodeTable, TileSpec
from siteline.schema import JSON, json_int, json_list, json_object

FORMAT_VERSION = 2


def write_index(root: zarr.Group, nodes: NodeTable) -> None:
    """Write ``nodes`` into the group ``root`` (a new store's)."""
    group = root.create_group("nodes")
    group.attrs.update({"tiles": list(nodes.tiles), "rows": len(nodes)})
    codec = BloscCodec(cname="zstd", clevel=5, shuffle=BloscShuffle.shuffle)
    for name, values in nodes.columns().items():
        values = np.ascontiguousarray(values)
        arr = group.create_array(
            name, shape=values.shape, dtype=values.dtype,
            chunks=tuple(max(v, 1) for v in values.shape), compressors=codec, fill_value=0,
        )  # fmt: skip
        if values.size:
            arr[...] = values


def read_index(root: zarr.Group, attrs: dict[str, JSON], spec: TileSpec, uri: str) -> NodeTable:
    """The node index of the store ``root`` (attributes ``attrs``) at ``uri``."""
    version = json_int(attrs.get("siteline_tiles", 0) or 0, "siteline_tiles")
    if version >= 2:
        try:
            group = root["nodes"]
        except KeyError as exc:
            raise TileError(f"tile store {uri} has no node index: tile the scene again.") from exc
        if not isinstance(group, zarr.Group):
            raise TileError(f"tile store {uri}: its node index is not a group: the store is damaged.")
        tiles = [str(t) for t in json_list(group.attrs.get("tiles", []), "tiles")]
        columns = {}
        for name in group.array_keys():
            arr = group[name]
            columns[name] = np.asarray(arr[...]) if isinstance(arr, zarr.Array) else None
        return NodeTable.from_columns(tiles, columns)
    if "nodes" not in attrs:
        raise TileError(f"{uri} is not a siteline tile store.")
    return NodeTable.from_legacy([json_object(n, "node") for n in json_list(attrs["nodes"], "nodes")], spec)
