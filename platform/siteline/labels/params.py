"""Label parameters (DESIGN.md §4): the change radius, given or derived from the point spacing."""

from __future__ import annotations

import math
from dataclasses import dataclass

from siteline.errors import LabelError


@dataclass(frozen=True)
class LabelParams:
    """radius_m: change radius in metres, or None for ``radius_multiplier`` x the median
    nearest-neighbour spacing of the sparser scene."""

    radius_m: float | None = None
    radius_multiplier: float = 2.5

    def __post_init__(self) -> None:
        if self.radius_m is not None and not (
            isinstance(self.radius_m, int | float) and math.isfinite(self.radius_m) and self.radius_m > 0
        ):
            raise LabelError(f"radius {self.radius_m!r} m must be a positive number or 'auto'.")
        if not (isinstance(self.radius_multiplier, int | float) and self.radius_multiplier > 0):
            raise LabelError("radius multiplier must be positive.")
