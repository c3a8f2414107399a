"""Mission ingest: inventory, validation, georegistration, the scene's catalog rows (DESIGN.md §1, §9).

The ingest stage: :func:`~siteline.ingest.plan.plan_ingest` (catalog) ->
:func:`~siteline.ingest.execute.execute_ingest` and ``store_mission`` (read, check, store) ->
``siteline.catalog.missions.record_ingest``; :func:`ingest_mission` runs them. Only the CLI, the flows
and ``siteline.pipeline`` import this package; the primitives it builds on (``siteline.photos``,
``siteline.sitestream``, ``siteline.hashing``, ``siteline.stores``) live below it.
"""

from siteline.ingest.options import IngestOptions
from siteline.ingest.stage import IngestResult, ingest_mission

__all__ = ["IngestOptions", "IngestResult", "ingest_mission"]
