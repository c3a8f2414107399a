"""Pairs of scenes: 3D change labels, synthetic views, rendered image pairs with change masks.

The pair stage: :func:`plan_pair` (catalog) -> :func:`execute_pair` (labels, views, renders) ->
``siteline.catalog.pairs.record_pair_outputs``; :func:`process_pair` runs them. Names are imported on
first use (PEP 562), so reading made outputs (``siteline.pairs.outputs``) or the parameters does not
pull in the renderer and torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from siteline.lazy import lazy_names

if TYPE_CHECKING:  # mypy and editors see the real signatures; nothing is imported at run time
    from siteline.pairs.execute import execute_pair as execute_pair
    from siteline.pairs.params import PairParams as PairParams
    from siteline.pairs.plan import PairPlan as PairPlan
    from siteline.pairs.plan import output_digest as output_digest
    from siteline.pairs.plan import plan_pair as plan_pair
    from siteline.pairs.render import LabelledPair as LabelledPair
    from siteline.pairs.render import PairRender as PairRender
    from siteline.pairs.render import pair_mask as pair_mask
    from siteline.pairs.render import render_pair_view as render_pair_view
    from siteline.pairs.stage import find_pair_output as find_pair_output
    from siteline.pairs.stage import process_pair as process_pair
    from siteline.records.pairs import PairOutput as PairOutput
    from siteline.records.pairs import PairVersions as PairVersions

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
