"""Pairs of scenes: 3D change labels, synthetic views, rendered image pairs with change masks."""

from siteline.pairs.params import PairParams
from siteline.pairs.process import PairOutput, output_digest, pair_output, process_pair
from siteline.pairs.render import PairRender, pair_mask, render_pair_view

__all__ = [
    "PairOutput",
    "PairParams",
    "PairRender",
    "pair_mask",
    "pair_output",
    "output_digest",
    "process_pair",
    "render_pair_view",
]
