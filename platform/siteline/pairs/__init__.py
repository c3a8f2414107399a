"""Pairs of scenes: 3D change labels, synthetic views, rendered image pairs with change masks.

The pair stage: :func:`plan_pair` (catalog) -> :func:`execute_pair` (labels, views, renders) ->
``siteline.catalog.pairs.record_pair_outputs``; :func:`process_pair` runs them. Names are imported on
first use (PEP 562), so reading made outputs (``siteline.pairs.outputs``) or the parameters does not
pull in the renderer and torch.
"""

from __future__ import annotations

from siteline.lazy import lazy_names

_WHERE = {
    "LabelledPair": "siteline.pairs.render",
    "PairOutput": "siteline.records.pairs",
    "PairParams": "siteline.pairs.params",
    "PairPlan": "siteline.pairs.plan",
    "PairRender": "siteline.pairs.render",
    "PairVersions": "siteline.records.pairs",
    "execute_pair": "siteline.pairs.execute",
    "find_pair_output": "siteline.pairs.stage",
    "output_digest": "siteline.pairs.plan",
    "pair_mask": "siteline.pairs.render",
    "plan_pair": "siteline.pairs.plan",
    "process_pair": "siteline.pairs.stage",
    "render_pair_view": "siteline.pairs.render",
}

__all__ = sorted(_WHERE)


__getattr__ = lazy_names(__name__, _WHERE)
