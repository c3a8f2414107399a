"""Pairs of scenes: 3D change labels, synthetic views, rendered image pairs with change masks.

The pair stage: :func:`plan_pair` (catalog) -> :func:`execute_pair` (labels, views, renders) ->
``siteline.catalog.pairs.record_pair_outputs``; :func:`process_pair` runs them."""

from siteline.pairs.execute import execute_pair
from siteline.pairs.params import PairParams
from siteline.pairs.plan import PairPlan, output_digest, plan_pair
from siteline.pairs.render import LabelledPair, PairRender, pair_mask, render_pair_view
from siteline.pairs.stage import find_pair_output, process_pair
from siteline.records.pairs import PairOutput, PairVersions

__all__ = [
    "LabelledPair",
    "PairOutput",
    "PairParams",
    "PairPlan",
    "PairRender",
    "PairVersions",
    "execute_pair",
    "find_pair_output",
    "output_digest",
    "pair_mask",
    "plan_pair",
    "process_pair",
    "render_pair_view",
]
