"""Versioned, immutable dataset releases: build, publish, verify, diff, query (DESIGN.md §8).

Build: ``plan.plan_release`` (catalog) -> ``build.execute_build`` (write the draft) ->
``siteline.catalog.releases.record_draft``; publish: ``plan.plan_publish`` -> ``publish.move_into_place``
-> ``siteline.catalog.releases.record_published``; ``stage`` runs them. Names are imported from their
modules; this front imports nothing."""
