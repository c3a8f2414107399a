"""Render parameters: the speed/accuracy knobs, persisted with every render (DESIGN.md §6)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from siteline.errors import RenderError
from siteline.specs import parse_spec

PRECISIONS = ("float32", "float64")


@dataclass(frozen=True)
class RenderSettings:
    """scale: fraction of the camera's image size (1, 1/2, 1/4, 1/8 ...).
    point_size_px: 1 (one pixel per point) or an odd disk diameter k (a point covers the pixels whose
    centres lie within k/2 px of its own pixel centre; nearer points still win).
    near_m: points with z_cam <= near_m are dropped (metres).
    precision: dtype of the projection arithmetic; float32 is faster, float64 agrees with pycolmap to
    1e-9 px. Coordinates are always site-local.
    chunk_points: points projected per batch; bounds temporary memory (~60 bytes per point).
    """

    scale: float = 0.125
    point_size_px: int = 1
    near_m: float = 1e-3
    precision: str = "float32"
    chunk_points: int = 2_000_000

    def __post_init__(self) -> None:
        if not (isinstance(self.scale, int | float) and math.isfinite(self.scale) and 0 < self.scale <= 4):
            raise RenderError(f"render scale {self.scale!r} must be in (0, 4].")
        if (
            not isinstance(self.point_size_px, int)
            or self.point_size_px < 1
            or self.point_size_px % 2 == 0
            or self.point_size_px > 15
        ):
            raise RenderError(f"point size {self.point_size_px!r} px must be an odd integer from 1 to 15.")
        if not (math.isfinite(self.near_m) and self.near_m > 0):
            raise RenderError(f"near plane {self.near_m!r} m must be a positive number.")
        if self.precision not in PRECISIONS:
            raise RenderError(f"precision {self.precision!r} must be one of {PRECISIONS}.")
        if not isinstance(self.chunk_points, int) or self.chunk_points < 1:
            raise RenderError(f"chunk_points {self.chunk_points!r} must be a positive integer.")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> RenderSettings:
        """From the JSON form; RenderError names an unknown key or a wrongly typed value."""
        return cls(**parse_spec(cls, doc, "render settings", RenderError))
