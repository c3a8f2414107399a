"""Pair processing parameters: every speed/accuracy knob of labels, views and renders, persisted with
the pair's outputs and a release's lineage."""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any

from siteline.errors import ReleaseError
from siteline.specs import parse_spec
from siteline.views import SAMPLER_VERSION, ViewParams


@dataclass(frozen=True)
class PairParams:
    """scale, point_size_px: render knobs (DESIGN.md §6). views: views kept per pair. radius_m: change
    radius in metres, or None for ``radius_multiplier`` x the median spacing of the sparser scene.
    lod_factor: level of detail read per view (1 = spacing within a pixel footprint). seed: view
    sampling. min_coverage: views covering less of the image at ``scale`` are rejected. sampler: the
    view sampler's version (pose snapping and keyed stratified sample, siteline.views.generate),
    recorded in the lineage and part of the outputs' key, so outputs of another sampler are not reused."""

    scale: float = 0.125
    point_size_px: int = 1
    views: int = 300
    radius_m: float | None = None
    radius_multiplier: float = 2.5
    lod_factor: float = 1.0
    seed: int = 0
    min_coverage: float = 0.5
    view_params: dict[str, Any] = field(default_factory=dict)
    sampler: str = SAMPLER_VERSION

    def __post_init__(self) -> None:
        if self.sampler != SAMPLER_VERSION:
            raise ReleaseError(
                f"view sampler {self.sampler!r} is not this version's ({SAMPLER_VERSION!r}); outputs of "
                "another sampler cannot be rebuilt: drop the 'sampler' key to use the current one."
            )
        if self.radius_m is not None and not (math.isfinite(self.radius_m) and self.radius_m > 0):
            raise ReleaseError(f"radius {self.radius_m!r} m must be a positive number or 'auto'.")
        if not self.radius_multiplier > 0:
            raise ReleaseError("radius multiplier must be positive.")
        if self.views < 1:
            raise ReleaseError(f"views must be at least 1, got {self.views}.")

    def view_params_obj(self) -> ViewParams:
        base = {
            "n_views": self.views,
            "seed": self.seed,
            "render_scale": self.scale,
            "min_coverage": self.min_coverage,
        }
        return ViewParams.from_dict({**base, **self.view_params})

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> PairParams:
        """From the JSON form; ReleaseError names an unknown key or a wrongly typed value."""
        return cls(**parse_spec(cls, doc, "pair parameters", ReleaseError))

    def digest(self) -> str:
        """Short stable hash naming this parameter set's outputs."""
        return hashlib.sha256(json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()[:12]
