"""Mission ingest: inventory, validation, georegistration, the scene's catalog rows (DESIGN.md §1, §9).

Only the CLI, the flows and ``siteline.pipeline`` import this package; the primitives it builds on
(``siteline.photos``, ``siteline.sitestream``, ``siteline.hashing``, ``siteline.stores``) live below it.
"""
