"""Rendering georeferenced (float64, CRS) points: shift to site-local in float64, then render.

The renderer itself never sees large coordinates (DESIGN.md §2).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import torch

from siteline.camera.pinhole import Camera
from siteline.errors import RenderError
from siteline.records.params.render import RenderParams
from siteline.render.zbuffer import RenderResult, render_points
from siteline.site.crs import site_from_crs


def to_site_local_f32(
    xyz_crs: np.ndarray, origin: Sequence[float], chunk_points: int = 4_000_000
) -> np.ndarray:
    """(N, 3) float64 georeferenced -> (N, 3) float32 site-local, in chunks (float64 subtraction first)."""
    xyz = np.asarray(xyz_crs)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise RenderError(f"georeferenced points must have shape (N, 3), got {xyz.shape}.")
    out = np.empty(xyz.shape, dtype=np.float32)
    for s in range(0, len(xyz), chunk_points):
        out[s : s + chunk_points] = site_from_crs(xyz[s : s + chunk_points], origin)
    return out


def render_georeferenced(
    xyz_crs: np.ndarray,
    origin: Sequence[float],
    camera: Camera,
    settings: RenderParams | None = None,
    attributes: Mapping[str, np.ndarray] | None = None,
    device: str | torch.device = "cpu",
) -> RenderResult:
    """Render float64 georeferenced points through ``camera``, whose world is the site-local frame
    of ``origin`` (float64, CRS units)."""
    return render_points(to_site_local_f32(xyz_crs, origin), camera, settings, attributes, device)
