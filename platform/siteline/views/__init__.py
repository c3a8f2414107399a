"""Synthetic views: ground plane, vertical / mirror / forward strategies, rejection, sampling (DESIGN.md §5)."""

from siteline.views.generate import (
    SAMPLER_VERSION,
    NamedCamera,
    SyntheticView,
    ViewSet,
    candidate_key,
    candidate_views,
    generate_views,
    strategy_key,
    stratified_sample,
)
from siteline.views.ground import GroundPlane, fit_ground_plane
from siteline.views.params import ViewParams
from siteline.views.sources import ArrayPointSource, PointSource
from siteline.views.strategies import forward, mirror, vertical

__all__ = [
    "SAMPLER_VERSION",
    "ArrayPointSource",
    "GroundPlane",
    "NamedCamera",
    "PointSource",
    "SyntheticView",
    "ViewParams",
    "ViewSet",
    "candidate_key",
    "candidate_views",
    "fit_ground_plane",
    "forward",
    "generate_views",
    "mirror",
    "stratified_sample",
    "strategy_key",
    "vertical",
]
