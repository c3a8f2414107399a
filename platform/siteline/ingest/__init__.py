"""Mission ingest: inventory, validation, georegistration, the scene's catalog rows (DESIGN.md §1, §9).

The ingest stage: :func:`~siteline.ingest.plan.plan_ingest` (catalog) ->
:func:`~siteline.ingest.execute.execute_ingest` and ``store_mission`` (read, check, store) ->
``siteline.catalog.missions.record_ingest``; :func:`ingest_mission` runs them. Only the CLI, the flows
and ``siteline.pipeline`` import this package; the primitives it builds on (``siteline.photos``,
``siteline.pointpass.sitestream``, ``siteline.hashing``, ``siteline.stores``) live below it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from siteline.lazy import lazy_names

if TYPE_CHECKING:  # mypy and editors see the real signatures; nothing is imported at run time
    from siteline.ingest.options import IngestOptions as IngestOptions
    from siteline.ingest.stage import IngestResult as IngestResult
    from siteline.ingest.stage import ingest_mission as ingest_mission

# imported on first use: a worker process that reads a point cloud needs none of the stage's catalog
_WHERE = {
    "IngestOptions": "siteline.ingest.options",
    "IngestResult": "siteline.ingest.stage",
    "ingest_mission": "siteline.ingest.stage",
}
__all__ = sorted(_WHERE)


__getattr__ = lazy_names(__name__, _WHERE)
