"""Synthetic views: ground plane, vertical / mirror / forward strategies, rejection, sampling (DESIGN.md §5).

Names are imported on first use (PEP 562): the persisted parameters (``siteline.views.params``) do not
pull in the renderer and torch.
"""

from __future__ import annotations

from siteline.lazy import lazy_names

_WHERE = {
    "SAMPLER_VERSION": "siteline.views.params",
    "ArrayPointSource": "siteline.views.sources",
    "GroundPlane": "siteline.views.ground",
    "NamedCamera": "siteline.views.generate",
    "PointSource": "siteline.views.sources",
    "SyntheticView": "siteline.views.generate",
    "ViewParams": "siteline.views.params",
    "ViewSet": "siteline.views.generate",
    "candidate_key": "siteline.views.generate",
    "candidate_views": "siteline.views.generate",
    "fit_ground_plane": "siteline.views.ground",
    "forward": "siteline.views.strategies",
    "generate_views": "siteline.views.generate",
    "mirror": "siteline.views.strategies",
    "stratified_sample": "siteline.views.generate",
    "strategy_key": "siteline.views.generate",
    "vertical": "siteline.views.strategies",
}

__all__ = sorted(_WHERE)


__getattr__ = lazy_names(__name__, _WHERE)
