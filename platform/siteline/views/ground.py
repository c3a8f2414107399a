"""Ground plane fit to ground-class points (RANSAC, then least squares on the inliers)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from siteline.errors import ViewsError


@dataclass(frozen=True)
class GroundPlane:
    """Plane n . x + d = 0 in site-local metres, unit normal n pointing up (n_z > 0)."""

    normal: tuple[float, float, float]
    d: float

    def height(self, xyz: np.ndarray) -> np.ndarray:
        """Signed height (metres) of points (..., 3) above the plane."""
        return np.asarray(xyz, dtype=np.float64) @ np.asarray(self.normal) + self.d

    def to_dict(self) -> dict:
        return {"normal": list(self.normal), "d": self.d}

    @classmethod
    def from_dict(cls, doc: dict) -> GroundPlane:
        nx, ny, nz = (float(v) for v in doc["normal"])
        return cls((nx, ny, nz), float(doc["d"]))


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
