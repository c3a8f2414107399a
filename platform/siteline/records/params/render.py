"""Render parameters: the speed/accuracy knobs, persisted with every render (DESIGN.md §6)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass

from siteline.errors import RenderError
from siteline.records.enums import PRECISIONS
from siteline.records.specs import parse_spec
from siteline.schema import JSON

# how big a point is drawn: one diameter for every point, or its local spacing seen from the camera
SPLAT_MODES = ("fixed", "world")
# a world splat's diameter as a multiple of the point spacing it stands for: points a spacing apart
# on a jittered grid leave no pixel uncovered from about sqrt(2); 1.5 closes most gaps of the level
# of detail's one-point-per-cube samples, and the gap fill the rest (docs/performance.md)
WORLD_SPLAT_FACTOR = 2.0
MAX_SPLAT_PX = 63
MAX_FILL_PX = 8


@dataclass(frozen=True)
class RenderParams:
    """scale: fraction of the camera's image size (1, 1/2, 1/4, 1/8 ...).
    point_size_px: 1 (one pixel per point) or an odd disk diameter k (a point covers the pixels whose
    centres lie within k/2 px of its own pixel centre; nearer points still win).
    near_m: points with z_cam <= near_m are dropped (metres).
    precision: dtype of the projection arithmetic; float32 is faster, float64 agrees with pycolmap to
    1e-9 px. Coordinates are always site-local.
    chunk_points: points projected per batch; bounds temporary memory (~60 bytes per point).
    splat_factor: a world splat's diameter in point spacings (WORLD_SPLAT_FACTOR by default): wider
    closes more gaps, and draws an object's edge that much beyond where its surface ends
    (docs/performance.md measures both against analytic truth).
    trim_edges: with world splats, give the pixels where a splat reaches past its surface's edge to
    the farther surface behind (siteline.render.edges); no effect on fixed splats.
    sparse_surfaces: with the trim, say unsure (RenderResult.unsure_of) the pixels whose winner lies
    behind the reach of a sparse surface's samples (a pole's; siteline.render.zbuffer, SPARSE_REACH).
    """

    scale: float = 0.125
    point_size_px: int = 1
    near_m: float = 1e-3
    precision: str = "float32"
    chunk_points: int = 2_000_000
    splat: str = "fixed"
    splat_max_px: int = 31
    fill_px: int = 0
    splat_factor: float = WORLD_SPLAT_FACTOR
    trim_edges: bool = False
    sparse_surfaces: bool = False

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
        if self.splat not in SPLAT_MODES:
            raise RenderError(f"splat {self.splat!r} must be one of {SPLAT_MODES}.")
        m = self.splat_max_px
        if not isinstance(m, int) or isinstance(m, bool) or not self.point_size_px <= m <= MAX_SPLAT_PX:
            raise RenderError(
                f"splat_max_px {m!r} must be an integer from the point size ({self.point_size_px}) to {MAX_SPLAT_PX}."
            )
        f = self.fill_px
        if not isinstance(f, int) or isinstance(f, bool) or not 0 <= f <= MAX_FILL_PX:
            raise RenderError(f"fill_px {f!r} must be an integer from 0 to {MAX_FILL_PX}.")
        k = self.splat_factor
        if not isinstance(k, int | float) or isinstance(k, bool) or not (math.isfinite(k) and 0.5 <= k <= 4):
            raise RenderError(
                f"splat_factor {k!r} must be a number from 0.5 to 4 (point spacings per world splat)."
            )

        if not isinstance(self.trim_edges, bool):
            raise RenderError(f"trim_edges {self.trim_edges!r} must be true or false.")
        if not isinstance(self.sparse_surfaces, bool):
            raise RenderError(f"sparse_surfaces {self.sparse_surfaces!r} must be true or false.")

    def to_dict(self) -> dict[str, JSON]:
        return asdict(self)

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> RenderParams:
        """From the JSON form; RenderError names an unknown key or a wrongly typed value."""
        return parse_spec(cls, doc, "render settings", RenderError)
