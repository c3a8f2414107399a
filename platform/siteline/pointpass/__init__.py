"""The point-pass engine: one pass over a LAS/LAZ file in the site frame, in parallel point ranges,
that feeds ingest's scan and cuts the points into tile runs for the tile stage.

Its surface (what ``ingest/`` and ``tiles/`` use):

- :mod:`~siteline.pointpass.lasio`: LAS/LAZ chunks (``open_las``, ``iter_chunks``, ``write_las``);
- :mod:`~siteline.pointpass.sitestream`: chunks in the site frame (``site_chunks``, ``source_transformer``);
- :mod:`~siteline.pointpass.partition`: the pass, ``pass_file(PassSource, ...)`` -> ``PassResult`` (each
  range's chunk visitors and the ``Partition`` of tile runs, cut by ``Slice``), the one entry ingest's
  scan and the tile stage call, and the ``PartitionCache`` ingest keeps partitions in;
- :mod:`~siteline.pointpass.lod` and :mod:`~siteline.pointpass.nodes`: a tile's level-of-detail assignment
  and node plan (``assign_levels``, ``block_ranks``, ``cube_counts``, ``plan_nodes``, ``NodePlan``);
- :mod:`~siteline.pointpass.resources`: ``TilingResources``, what a tiling may use;
- :mod:`~siteline.pointpass.schema`: the point record (``RECORD``, ``COUNTS``, ``ATTRIBUTES``), its
  quantisation (``quantise``, ``dequantise``) and the bit layout of every packed key;
- :mod:`~siteline.pointpass.workers` (process pools) and :mod:`~siteline.pointpass.kernels` (numba loops:
  callers outside the engine use ``scatter_rows``, ``split_records`` and the ``kernel`` decorator from here).

"""

from __future__ import annotations

from siteline.pointpass.kernels import kernel
from siteline.pointpass.kernels.rows import scatter_rows, split_records
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

__all__ = [
    "ATTRIBUTES", "COUNTS", "PARALLEL_MIN_POINTS", "RECORD", "NodePlan", "Partition", "PartitionCache",
    "PassResult", "PassSource", "Slice", "TilingResources", "add_cube_counts", "assign_levels", "block_ranks",
    "cube_counts", "dequantise", "kernel", "pass_file", "plan_nodes", "quantise", "scatter_rows",
    "split_records",
]  # fmt: skip
