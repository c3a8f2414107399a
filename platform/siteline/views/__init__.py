"""Synthetic views: ground plane, vertical / mirror / forward strategies, rejection, sampling (DESIGN.md §5).

Names are imported on first use (PEP 562): the persisted parameters (``siteline.views.params``) do not
pull in the renderer and torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from siteline.lazy import lazy_names

if TYPE_CHECKING:  # mypy and editors see the real signatures; nothing is imported at run time
    from siteline.views.generate import NamedCamera as NamedCamera
    from siteline.views.generate import SyntheticView as SyntheticView
    from siteline.views.generate import ViewSet as ViewSet
    from siteline.views.generate import candidate_key as candidate_key
    from siteline.views.generate import candidate_views as candidate_views
    from siteline.views.generate import generate_views as generate_views
    from siteline.views.generate import strategy_key as strategy_key
    from siteline.views.generate import stratified_sample as stratified_sample
    from siteline.views.ground import GroundPlane as GroundPlane
    from siteline.views.ground import fit_ground_plane as fit_ground_plane
    from siteline.views.params import SAMPLER_VERSION as SAMPLER_VERSION
    from siteline.views.params import ViewParams as ViewParams
    from siteline.views.sources import ArrayPointSource as ArrayPointSource
    from siteline.views.sources import PointSource as PointSource
    from siteline.views.strategies import forward as forward
    from siteline.views.strategies import mirror as mirror
    from siteline.views.strategies import vertical as vertical

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
