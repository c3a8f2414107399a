"""Pairs of scenes: 3D change labels, synthetic views, rendered image pairs with change masks.

The pair stage: ``plan.plan_pair`` (catalog) -> ``execute.execute_pair`` (labels, views, renders) ->
``siteline.catalog.pairs.record_pair_outputs``; ``stage.process_pair`` runs them. Names are imported
from their modules; this front imports nothing."""
