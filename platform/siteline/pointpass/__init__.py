"""The point-pass engine: one pass over a LAS/LAZ file in the site frame, in parallel point ranges,
that feeds ingest's scan and cuts the points into tile runs for the tile stage.

Its front (the names below) is all that code outside the engine imports (held by
``tests/test_layers.py``): the pass (``pass_file(PassSource, ...)`` -> ``PassResult``, the ``Partition``
of tile runs cut by ``Slice``, the ``PartitionCache`` ingest keeps partitions in); LAS/LAZ files
(``open_las``, ``LasWriter``, ``write_las``, headers and the labels VLR); chunks in the site frame
(``site_chunks``, ``read_site_local``, ``source_transformer``, ``Correction``); the point record and its
quantisation (``RECORD``, ``quantise``, ``dequantise``; every packed key's layout is in ``schema.py``);
a tile's levels and node plan; ``TilingResources``; the process pools; the row movers and the ``kernel``
decorator. The modules behind it are the engine's own.

Each name is loaded from its module when first asked for (PEP 562), so importing one (``open_las``)
does not import numba, which the kernels need (0.24-0.34 s).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from siteline.pointpass.kernels import kernel
    from siteline.pointpass.kernels.rows import scatter_rows, split_records
    from siteline.pointpass.lasio import (
        LasHeaderFacts,
        LasWriter,
        detect_eight_bit,
        fill_record,
        header_facts,
        labels_vlr,
        las_header,
        open_las,
        read_labels_vlr,
        write_changed_classes,
        write_las,
    )
    from siteline.pointpass.lod import assign_levels, block_ranks
    from siteline.pointpass.nodes import NodePlan, add_cube_counts, cube_counts, plan_nodes
    from siteline.pointpass.partition import (
        PARALLEL_MIN_POINTS,
        Partition,
        PartitionCache,
        PassResult,
        PassSource,
        Slice,
        pass_file,
    )
    from siteline.pointpass.resources import TilingResources
    from siteline.pointpass.schema import ATTRIBUTES, COUNTS, RECORD, dequantise, quantise
    from siteline.pointpass.sitestream import (
        Correction,
        SiteChunk,
        SiteReading,
        correction_rigid,
        file_crs,
        read_site_local,
        site_chunks,
        source_crs,
        source_transformer,
    )
    from siteline.pointpass.workers import pool_map, process_pool, shutdown_pools, start_pool

# where each name of the front lives
_FRONT: dict[str, str] = {
    "kernel": "kernels",
    "scatter_rows": "kernels.rows",
    "split_records": "kernels.rows",
    "LasHeaderFacts": "lasio",
    "LasWriter": "lasio",
    "detect_eight_bit": "lasio",
    "fill_record": "lasio",
    "header_facts": "lasio",
    "labels_vlr": "lasio",
    "las_header": "lasio",
    "open_las": "lasio",
    "read_labels_vlr": "lasio",
    "write_changed_classes": "lasio",
    "write_las": "lasio",
    "assign_levels": "lod",
    "block_ranks": "lod",
    "NodePlan": "nodes",
    "add_cube_counts": "nodes",
    "cube_counts": "nodes",
    "plan_nodes": "nodes",
    "PARALLEL_MIN_POINTS": "partition",
    "Partition": "partition",
    "PartitionCache": "partition",
    "PassResult": "partition",
    "PassSource": "partition",
    "Slice": "partition",
    "pass_file": "partition",
    "TilingResources": "resources",
    "ATTRIBUTES": "schema",
    "COUNTS": "schema",
    "RECORD": "schema",
    "dequantise": "schema",
    "quantise": "schema",
    "Correction": "sitestream",
    "SiteChunk": "sitestream",
    "SiteReading": "sitestream",
    "correction_rigid": "sitestream",
    "file_crs": "sitestream",
    "read_site_local": "sitestream",
    "site_chunks": "sitestream",
    "source_crs": "sitestream",
    "source_transformer": "sitestream",
    "pool_map": "workers",
    "process_pool": "workers",
    "shutdown_pools": "workers",
    "start_pool": "workers",
}
__all__ = sorted(_FRONT)


def __getattr__(name: str) -> Any:
    module = _FRONT.get(name)
    if module is None:
        raise AttributeError(f"module 'siteline.pointpass' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"siteline.pointpass.{module}"), name)
    globals()[name] = value
    return value
