"""Ground from geometry, for clouds whose classes do not say it (class 0 or 1 only: a scanner's raw
cloud, an SfM cloud, a tiled archive): a progressive morphological filter (Zhang et al. 2003).

The lowest point of each cell of a plan grid is opened (a grey-scale erosion then dilation) with
square windows whose half-width doubles from one cell to ``max_window_m``; where the opening lowers a
cell by more than the window's height threshold (``dh0_m`` plus ``slope`` x twice the half-width, at
most ``dh_max_m``) that cell held an object, and the opened height is kept. A point is ground when it
lies within ``dh0_m`` of the final surface. Objects up to about twice ``max_window_m`` across are
removed; terrain steeper than ``slope`` is cut at its breaks.

Measured against the cloth simulation filter (the ``cloth-simulation-filter`` package, as CloudCompare
uses) on two real airborne clouds (bench/ground.py, docs/performance.md): on a flat town, precision /
recall 0.99 / 0.95 against the filter's 0.95 / 0.94 (1 m cloth); on wooded hills 0.79 / 0.87 against
0.79 / 0.75; 6-35x faster, and no extra dependency.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import ndimage


@dataclass(frozen=True)
class MorphologyParams:
    """The filter's knobs (module docstring): metres, and ``slope`` as rise over run."""

    cell_m: float = 2.0
    max_window_m: float = 20.0
    slope: float = 0.3
    dh0_m: float = 0.3
    dh_max_m: float = 3.0

    def to_dict(self) -> dict:
        return asdict(self)


def morphological_ground(xyz: np.ndarray, params: MorphologyParams = MorphologyParams()) -> np.ndarray:
    """(N,) bool: the ground points of a cloud (N, 3) site-local metres (module docstring). Costs a
    pass over the points and a few openings of a grid of the cloud's extent."""
    pts = np.asarray(xyz, dtype=np.float64)
    out = np.zeros(len(pts), dtype=bool)
    finite = np.isfinite(pts).all(axis=1)
    if finite.sum() < 3:
        return out
    p = pts[finite]
    cell = params.cell_m
    ij = np.floor((p[:, :2] - p[:, :2].min(axis=0)) / cell).astype(np.int64)
    nx, ny = (ij.max(axis=0) + 1).tolist()
    low = np.full((nx, ny), np.inf)
    np.minimum.at(low, (ij[:, 0], ij[:, 1]), p[:, 2])
    empty = ~np.isfinite(low)
    if empty.any():
        nearest = ndimage.distance_transform_edt(empty, return_distances=False, return_indices=True)
        low = low[tuple(nearest)]
    surface = low.copy()
    w = 1
    while w * cell <= params.max_window_m:
        opened = ndimage.grey_opening(surface, size=(2 * w + 1, 2 * w + 1))
        dh = min(params.dh_max_m, params.dh0_m + params.slope * 2 * w * cell)
        surface = np.where(surface - opened > dh, opened, surface)
        w *= 2
    # the surface between cell centres, bilinear: a cell's lowest point lies anywhere in it, so on a
    # slope the cell's own value alone would leave its uphill side above the threshold
    f = (p[:, :2] - p[:, :2].min(axis=0)) / cell - 0.5
    f[:, 0] = np.clip(f[:, 0], 0.0, nx - 1.0)
    f[:, 1] = np.clip(f[:, 1], 0.0, ny - 1.0)
    i0 = np.minimum(np.floor(f).astype(np.int64), np.maximum(np.array([nx, ny]) - 2, 0))
    i1 = np.minimum(i0 + 1, np.array([nx - 1, ny - 1]))
    t = f - i0
    z = (
        surface[i0[:, 0], i0[:, 1]] * (1 - t[:, 0]) * (1 - t[:, 1])
        + surface[i1[:, 0], i0[:, 1]] * t[:, 0] * (1 - t[:, 1])
        + surface[i0[:, 0], i1[:, 1]] * (1 - t[:, 0]) * t[:, 1]
        + surface[i1[:, 0], i1[:, 1]] * t[:, 0] * t[:, 1]
    )
    out[np.flatnonzero(finite)] = p[:, 2] - z < params.dh0_m
    return out
