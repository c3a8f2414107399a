"""The point-pass engine: one pass over a LAS/LAZ file in the site frame, in parallel point ranges,
that feeds ingest's scan and cuts the points into tile runs for the tile stage.

Its surface (what ``ingest/`` and ``tiles/`` use):

- :mod:`~siteline.pointpass.lasio`: LAS/LAZ chunks (``open_las``, ``iter_chunks``, ``write_las``);
- :mod:`~siteline.pointpass.sitestream`: chunks in the site frame (``site_chunks``, ``source_transformer``);
- :mod:`~siteline.pointpass.partition`: the pass, ``pass_file(PassSource, ...)`` -> ``PassResult`` (each
  range's chunk visitors and the ``Partition`` of tile runs, cut by ``Slice``), the one entry ingest's
  scan and the tile stage call, and the ``PartitionCache`` ingest keeps partitions in;
- :mod:`~siteline.pointpass.resources`: ``TilingResources``, what a tiling may use;
- :mod:`~siteline.pointpass.schema`: the point record and the bit layout of every packed key;
- :mod:`~siteline.pointpass.workers` (process pools) and :mod:`~siteline.pointpass.kernels` (numba loops).

"""

from __future__ import annotations

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
from siteline.pointpass.schema import RECORD

__all__ = [
    "PARALLEL_MIN_POINTS", "RECORD", "Partition", "PartitionCache", "PassResult", "PassSource", "Slice",
    "TilingResources", "pass_file",
]  # fmt: skip
