"""Mission ingest: inventory, validation, georegistration, the scene's catalog rows (DESIGN.md §1, §9).

The ingest stage: ``plan.plan_ingest`` (catalog) -> ``execute.execute_ingest`` and ``store_mission``
(read, check, store) -> ``siteline.catalog.missions.record_ingest``; ``stage.ingest_mission`` runs them.
Only the CLI, the flows and ``siteline.pipeline`` import the stage; names are imported from their
modules (this front imports nothing)."""
