"""The ground views are placed against: a plane fit to ground points (RANSAC, then least squares on
the inliers), or a terrain grid where the ground is not a plane (siteline.views.terrain); the ground
points are the ground class's, or found from geometry where no class gives them
(siteline.views.groundfilter). :func:`model_ground` chooses, and says what it chose."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from siteline.errors import ViewsError
from siteline.views.groundfilter import MorphologyParams, morphological_ground
from siteline.views.terrain import TerrainGrid, terrain_grid

# the ground class is used when it holds at least this many points and a share of the cloud a real
# survey has (a cloud that is all ground, or all but a handful, carries no ground class that helps)
MIN_GROUND_POINTS = 50
GROUND_SHARE = (0.005, 0.995)
# a plane is kept while the terrain rises above it by no more than this (95th percentile of the
# cells that hold ground, metres): ground above the plane is what puts a lowered camera under it;
# ground below it (a pit, an excavation) leaves cameras higher than planned, never under the ground
PLANE_TOLERANCE_M = 1.0


@dataclass(frozen=True)
class GroundPlane:
    """Plane n . x + d = 0 in site-local metres, unit normal n pointing up (n_z > 0)."""

    normal: tuple[float, float, float]
    d: float

    def height(self, xyz: np.ndarray) -> np.ndarray:
        """Signed height (metres) of points (..., 3) above the plane."""
        return np.asarray(xyz, dtype=np.float64) @ np.asarray(self.normal) + self.d

    @property
    def up(self) -> tuple[float, float, float]:
        """The direction cameras move along to change their height: the plane's normal."""
        return self.normal

    def z_at(self, xy: np.ndarray) -> np.ndarray:
        """(...,) the plane's height below each (..., 2) place."""
        p = np.asarray(xy, dtype=np.float64)
        n = self.normal
        return -(n[0] * p[..., 0] + n[1] * p[..., 1] + self.d) / n[2]

    def point_below(self, xy: np.ndarray) -> np.ndarray:
        """(3,) the plane's point below the place ``xy`` (2,)."""
        p = np.asarray(xy, dtype=np.float64)[:2]
        return np.array([p[0], p[1], float(self.z_at(p))])

    def axis_hit(self, center: np.ndarray, forward: np.ndarray) -> np.ndarray | None:
        """(3,) where the ray from ``center`` along unit ``forward`` meets the plane, or None when it
        looks level or up, or away from it."""
        n = np.asarray(self.normal, dtype=np.float64)
        C, f = np.asarray(center, np.float64), np.asarray(forward, np.float64)
        denom = float(f @ n)
        if denom >= -1e-6:
            return None
        t = -float(self.height(C[None])[0]) / denom
        return C + t * f if t > 0 else None

    def to_dict(self) -> dict:
        return {"normal": list(self.normal), "d": self.d}

    @classmethod
    def from_dict(cls, doc: dict) -> GroundPlane:
        nx, ny, nz = (float(v) for v in doc["normal"])
        return cls((nx, ny, nz), float(doc["d"]))

    def keep_height(self, before: np.ndarray, after: np.ndarray) -> np.ndarray:
        """A camera moved in plan from ``before`` to ``after`` (3,): the plane model leaves it where it
        was put (a mirror across the fence keeps its z, as views have been placed since the first
        release)."""
        return np.asarray(after, dtype=np.float64)


class GroundModel(Protocol):
    """What view generation asks of the ground: site-local metres throughout."""

    @property
    def up(self) -> tuple[float, float, float]: ...

    def height(self, xyz: np.ndarray) -> np.ndarray: ...

    def point_below(self, xy: np.ndarray) -> np.ndarray: ...

    def axis_hit(self, center: np.ndarray, forward: np.ndarray) -> np.ndarray | None: ...

    def keep_height(self, before: np.ndarray, after: np.ndarray) -> np.ndarray: ...

    def to_dict(self) -> dict: ...


def _plane_through(p: np.ndarray) -> tuple[np.ndarray, float] | None:
    n = np.cross(p[1] - p[0], p[2] - p[0])
    norm = np.linalg.norm(n)
    if norm < 1e-9:
        return None
    n = n / norm
    return n, -float(n @ p[0])


def fit_ground_plane(
    xyz: np.ndarray,
    *,
    inlier_m: float = 0.25,
    iterations: int = 256,
    max_tilt_deg: float = 30.0,
    seed: int = 0,
    max_points: int = 200_000,
) -> GroundPlane:
    """Robust plane through ground points (N, 3) site-local metres.

    RANSAC (seeded) keeps the plane with most points within ``inlier_m``, among planes tilted less than
    ``max_tilt_deg`` from horizontal; a least-squares fit (SVD) on those inliers refines it. Outliers
    (machines, piles, noise) do not move it. Raises :class:`ViewsError` with fewer than 3 points or no
    plausible plane.
    """
    pts = np.asarray(xyz, dtype=np.float64)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) < 3:
        raise ViewsError(f"need at least 3 ground points to fit the ground plane, got {len(pts)}.")
    rng = np.random.default_rng(seed)
    if len(pts) > max_points:
        pts = pts[rng.choice(len(pts), max_points, replace=False)]
    min_nz = np.cos(np.deg2rad(max_tilt_deg))
    best, best_count = None, -1
    for _ in range(iterations):
        plane = _plane_through(pts[rng.choice(len(pts), 3, replace=False)])
        if plane is None:
            continue
        n, d = plane
        if n[2] < 0:
            n, d = -n, -d
        if n[2] < min_nz:
            continue
        count = int((np.abs(pts @ n + d) < inlier_m).sum())
        if count > best_count:
            best, best_count = (n, d), count
    if best is None:
        raise ViewsError(
            "no near-horizontal plane fits the ground points (all collinear or steeper than "
            f"{max_tilt_deg} degrees)."
        )
    n, d = best
    inl = pts[np.abs(pts @ n + d) < inlier_m]
    centroid = inl.mean(axis=0)
    _, _, vt = np.linalg.svd(inl - centroid, full_matrices=False)
    n = vt[2]
    if n[2] < 0:
        n = -n
    return GroundPlane((float(n[0]), float(n[1]), float(n[2])), float(-n @ centroid))


@dataclass(frozen=True)
class GroundChoice:
    """The ground of one scene as view generation uses it: the ``model`` (a plane or a terrain grid),
    where its points came from (``source``: ``class``, the ground class; ``morphology``, found from
    geometry with ``filter`` params), how many and what share of the points read they are, and how far
    the terrain rises above the best plane (``residual_m``, 95th percentile over the cells holding
    ground, 0 where it lies below; the model is the plane when it is within ``tolerance_m``)."""

    model: GroundModel
    source: str
    ground_points: int
    share: float
    residual_m: float
    tolerance_m: float
    plane: GroundPlane
    filter: dict | None = None

    @property
    def kind(self) -> str:
        return "plane" if isinstance(self.model, GroundPlane) else "terrain"

    def to_dict(self) -> dict:
        return {
            "model": self.kind, "source": self.source, "ground_points": self.ground_points, "share": self.share,
            "residual_m": self.residual_m, "tolerance_m": self.tolerance_m, "filter": self.filter,
            "cell_m": self.model.cell_m if isinstance(self.model, TerrainGrid) else None,
            "plane": self.plane.to_dict(), **({"terrain": self.model.to_dict()} if self.kind == "terrain" else {}),
        }  # fmt: skip


def usable_ground_class(on_ground: np.ndarray) -> bool:
    """Whether a ground-class mask (N,) bool is one to trust: MIN_GROUND_POINTS and a share within
    GROUND_SHARE."""
    n = int(np.count_nonzero(on_ground))
    share = n / max(len(on_ground), 1)
    return n >= MIN_GROUND_POINTS and GROUND_SHARE[0] <= share <= GROUND_SHARE[1]


def model_ground(
    xyz: np.ndarray,
    on_ground: np.ndarray,
    seed: int = 0,
    tolerance_m: float = PLANE_TOLERANCE_M,
    morphology: MorphologyParams = MorphologyParams(),
) -> GroundChoice:
    """The ground of a cloud (N, 3) site-local metres whose ground class is ``on_ground`` (N,) bool:
    that class when :func:`usable_ground_class`, else the morphological filter's ground; a plane fit
    to it, kept when the terrain grid rises above it by at most ``tolerance_m`` (95th percentile), else
    the grid.
    :class:`ViewsError` when neither gives 3 ground points."""
    pts = np.asarray(xyz, dtype=np.float64)
    mask = np.asarray(on_ground, dtype=bool)
    source, params = "class", None
    if not usable_ground_class(mask):
        mask = morphological_ground(pts, morphology)
        source, params = "morphology", morphology.to_dict()
    ground = pts[mask]
    if len(ground) < 3:
        raise ViewsError(
            f"found {len(ground)} ground points in {len(pts):,} (by {source}); views need the ground to stand on."
        )
    plane = fit_ground_plane(ground, seed=seed)
    grid, held = terrain_grid(ground)
    rise = np.maximum(grid.z - plane_heights(plane, grid), 0.0)[held]
    residual = float(np.percentile(rise, 95))
    model: GroundModel = plane if residual <= tolerance_m else grid
    return GroundChoice(
        model, source, len(ground), len(ground) / max(len(pts), 1), residual, tolerance_m, plane, params
    )


def plane_heights(plane: GroundPlane, grid: TerrainGrid) -> np.ndarray:
    """(ny, nx) the plane's height below each cell centre of ``grid``."""
    ny, nx = grid.z.shape
    x = grid.x0 + (np.arange(nx) + 0.5) * grid.cell_m
    y = grid.y0 + (np.arange(ny) + 0.5) * grid.cell_m
    return plane.z_at(np.stack(np.meshgrid(x, y), axis=-1))
