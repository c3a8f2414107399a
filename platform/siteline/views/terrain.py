"""Terrain: a height grid of the ground, for sites that are not a plane (a hillside, a quarry, a pit).

The grid holds the mean height of the ground points in each cell (site-local metres), cells without
ground filled from the nearest cell that has some (under a building, beyond the scan). Heights between
cell centres are bilinear; beyond the grid, the edge cells' heights continue. It answers the same
questions as :class:`siteline.views.ground.GroundPlane`: a point's height above the ground below it,
where a camera's optical axis meets the ground, the ground below a place; cameras move along world up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from siteline.errors import ViewsError

# a cell spans this many ground-point spacings (several points a cell), within these bounds (metres)
CELL_SPACINGS = 3.0
MIN_CELL_M = 1.0
MAX_CELL_M = 10.0
# the optical axis is followed in steps of this share of a cell, up to this many metres
AXIS_STEP_CELLS = 0.5
AXIS_REACH_M = 5_000.0


def grid_cell_m(ground_xyz: np.ndarray) -> float:
    """The cell (metres) a set of ground points (N, 3) supports: CELL_SPACINGS x their spacing
    (the square root of the area of the 1 m cells they occupy over their number), within
    [MIN_CELL_M, MAX_CELL_M]."""
    ij = np.unique(np.floor(np.asarray(ground_xyz, np.float64)[:, :2]).astype(np.int64), axis=0)
    spacing = float(np.sqrt(len(ij) / max(len(ground_xyz), 1)))
    return float(np.clip(CELL_SPACINGS * spacing, MIN_CELL_M, MAX_CELL_M))


@dataclass(frozen=True)
class TerrainGrid:
    """Ground heights ``z`` (ny, nx) float64 metres at the centres of square cells of ``cell_m``,
    cell (0, 0) spanning [x0, x0 + cell_m) x [y0, y0 + cell_m) in the site-local frame."""

    x0: float
    y0: float
    cell_m: float
    z: np.ndarray

    @property
    def up(self) -> tuple[float, float, float]:
        """The direction cameras move along to change their height: world up."""
        return (0.0, 0.0, 1.0)

    def z_at(self, xy: np.ndarray) -> np.ndarray:
        """(...,) ground height (metres) below each (..., 2) place: bilinear between cell centres,
        the edge heights beyond the grid."""
        p = np.asarray(xy, dtype=np.float64)
        ny, nx = self.z.shape
        fx = np.clip((p[..., 0] - self.x0) / self.cell_m - 0.5, 0.0, nx - 1.0)
        fy = np.clip((p[..., 1] - self.y0) / self.cell_m - 0.5, 0.0, ny - 1.0)
        i0 = np.minimum(np.floor(fx).astype(np.int64), max(nx - 2, 0))
        j0 = np.minimum(np.floor(fy).astype(np.int64), max(ny - 2, 0))
        i1, j1 = np.minimum(i0 + 1, nx - 1), np.minimum(j0 + 1, ny - 1)
        tx, ty = fx - i0, fy - j0
        z = self.z
        top = z[j0, i0] * (1 - tx) + z[j0, i1] * tx
        bottom = z[j1, i0] * (1 - tx) + z[j1, i1] * tx
        return top * (1 - ty) + bottom * ty

    def height(self, xyz: np.ndarray) -> np.ndarray:
        """(...,) height (metres) of points (..., 3) above the ground below them."""
        p = np.asarray(xyz, dtype=np.float64)
        return p[..., 2] - self.z_at(p[..., :2])

    def point_below(self, xy: np.ndarray) -> np.ndarray:
        """(3,) the ground point below the place ``xy`` (2,)."""
        p = np.asarray(xy, dtype=np.float64)[:2]
        return np.array([p[0], p[1], float(self.z_at(p))])

    def axis_hit(self, center: np.ndarray, forward: np.ndarray) -> np.ndarray | None:
        """(3,) where the ray from ``center`` along unit ``forward`` first meets the ground (steps of
        half a cell, then bisection to a millimetre), or None when it looks level or up, starts
        under the ground, or meets none within AXIS_REACH_M."""
        C, f = np.asarray(center, np.float64), np.asarray(forward, np.float64)
        if f[2] >= -1e-6 or self.height(C) <= 0:
            return None
        step = AXIS_STEP_CELLS * self.cell_m
        t = np.arange(1, int(AXIS_REACH_M / step) + 1) * step
        h = self.height(C[None, :] + t[:, None] * f[None, :])
        below = np.flatnonzero(h <= 0)
        if not len(below):
            return None
        k = int(below[0])
        lo, hi = (t[k - 1] if k else 0.0), t[k]
        while hi - lo > 1e-3:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.height(C + mid * f) > 0 else (lo, mid)
        return C + hi * f

    def keep_height(self, before: np.ndarray, after: np.ndarray) -> np.ndarray:
        """A camera moved in plan from ``before`` to ``after`` (3,), lifted or lowered to keep its
        height above the ground below it."""
        out = np.asarray(after, dtype=np.float64).copy()
        out[2] = float(self.z_at(out[:2])) + float(self.height(np.asarray(before, dtype=np.float64)))
        return out

    def to_dict(self) -> dict:
        """Where it lies and how coarse it is (the heights themselves are not recorded)."""
        ny, nx = self.z.shape
        return {
            "model": "terrain", "cell_m": self.cell_m, "origin": [self.x0, self.y0], "shape": [ny, nx],
            "z_range_m": [float(self.z.min()), float(self.z.max())],
        }  # fmt: skip


def terrain_grid(ground_xyz: np.ndarray, cell_m: float | None = None) -> tuple[TerrainGrid, np.ndarray]:
    """The terrain grid of ground points (N, 3) site-local metres at ``cell_m`` (None: what their
    density supports, :func:`grid_cell_m`), and (ny, nx) bool the cells that held ground (the rest
    were filled from the nearest that did)."""
    pts = np.asarray(ground_xyz, dtype=np.float64)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) < 3:
        raise ViewsError(f"a terrain needs at least 3 ground points, got {len(pts)}.")
    cell = grid_cell_m(pts) if cell_m is None else float(cell_m)
    x0, y0 = float(np.floor(pts[:, 0].min() / cell) * cell), float(np.floor(pts[:, 1].min() / cell) * cell)
    i = np.floor((pts[:, 0] - x0) / cell).astype(np.int64)
    j = np.floor((pts[:, 1] - y0) / cell).astype(np.int64)
    nx, ny = int(i.max()) + 1, int(j.max()) + 1
    total = np.zeros((ny, nx))
    count = np.zeros((ny, nx))
    np.add.at(total, (j, i), pts[:, 2])
    np.add.at(count, (j, i), 1.0)
    held = count > 0
    z = np.where(held, total / np.maximum(count, 1.0), 0.0)
    if not held.all():
        nearest = ndimage.distance_transform_edt(~held, return_distances=False, return_indices=True)
        z = z[tuple(nearest)]
    return TerrainGrid(x0, y0, cell, z), held
