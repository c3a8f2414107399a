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

Names are imported on first use, so importing one module (``lasio`` for a LAS writer) pulls in no other.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from siteline.lazy import lazy_names

if TYPE_CHECKING:  # mypy and editors see the real signatures; nothing is imported at run time
    from siteline.pointpass.partition import Partition as Partition
    from siteline.pointpass.partition import PartitionCache as PartitionCache
    from siteline.pointpass.partition import PassSource as PassSource
    from siteline.pointpass.partition import Slice as Slice
    from siteline.pointpass.resources import TilingResources as TilingResources
    from siteline.pointpass.schema import RECORD as RECORD

_WHERE = {
    "Partition": "siteline.pointpass.partition",
    "PartitionCache": "siteline.pointpass.partition",
    "PassSource": "siteline.pointpass.partition",
    "Slice": "siteline.pointpass.partition",
    "TilingResources": "siteline.pointpass.resources",
    "RECORD": "siteline.pointpass.schema",
}
__all__ = sorted(_WHERE)

__getattr__ = lazy_names(__name__, _WHERE)
