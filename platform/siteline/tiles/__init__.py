"""The Zarr v3 tile store: site-grid tiles with an additive level of detail (DESIGN.md §2, §7).

The tile stage: ``plan.plan_tiling`` (catalog) -> ``execute.execute_tiling`` (write and publish the
store) -> ``siteline.catalog.scenes.record_tiling``; ``stage.tile_scene`` runs the three. Names are
imported from their modules (this front imports nothing)."""
