"""The point-pass engine: one pass over a LAS/LAZ file in the site frame, in parallel point ranges,
that feeds ingest's scan and cuts the points into tile runs for the tile stage.

Its surface (what ``ingest/`` and ``tiles/`` use):

- :mod:`~siteline.pointpass.lasio`: LAS/LAZ chunks (``open_las``, ``iter_chunks``, ``write_las``);
- :mod:`~siteline.pointpass.sitestream`: chunks in the site frame (``site_chunks``, ``source_transformer``);
- :mod:`~siteline.pointpass.partition`: the pass (``read_file`` over ``PassSource`` with chunk visitors,
  ``RunWriter``), its runs (``Partition``, ``Slice``) and the ``PartitionCache`` ingest keeps them in;
- :mod:`~siteline.pointpass.resources`: ``TilingResources``, what a tiling may use;
- :mod:`~siteline.pointpass.schema`: the point record and the bit layout of every packed key;
- :mod:`~siteline.pointpass.workers` (process pools) and :mod:`~siteline.pointpass.kernels` (numba loops).

"""

from __future__ import annotations

from siteline.pointpass.partition import Partition, PartitionCache, PassSource, Slice
from siteline.pointpass.resources import TilingResources
from siteline.pointpass.schema import RECORD

__all__ = ["RECORD", "Partition", "PartitionCache", "PassSource", "Slice", "TilingResources"]
