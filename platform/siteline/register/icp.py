"""Point-to-plane ICP between two scenes' stable-class samples: an alignment check, not a correction."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from siteline.poses import Rigid


@dataclass
class AlignmentCheck:
    """Result of aligning a new scene's sample onto the previous scene's.

    residual_m: RMS point-to-plane distance of the matched points after alignment.
    translation_m, rotation_deg: the rigid correction ICP found (what the new scene is off by).
    prev_from_new: that correction as a pose, site-local metres of the new scene -> the previous one.
    matched: matched point pairs; degenerate: the geometry cannot fix every direction (a flat scene),
    so the correction along unconstrained directions is reported as zero.
    """

    residual_m: float
    translation_m: float
    rotation_deg: float
    prev_from_new: Rigid
    matched: int
    degenerate: bool
    iterations: int

    @property
    def correction(self) -> list[list[float]]:
        """``prev_from_new`` as a (4, 4) homogeneous matrix (nested lists)."""
        return self.prev_from_new.matrix().tolist()

    def to_dict(self) -> dict:
        return {
            "residual_m": self.residual_m,
            "translation_m": self.translation_m,
            "rotation_deg": self.rotation_deg,
            "correction": self.correction,
            "correction_frames": self.prev_from_new.name,
            "matched": self.matched,
            "degenerate": self.degenerate,
            "iterations": self.iterations,
        }


def _normals(tree: cKDTree, pts: np.ndarray, k: int = 12) -> np.ndarray:
    _, idx = tree.query(pts, k=min(k, len(pts)))
    nb = pts[idx] - pts[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    _, vecs = np.linalg.eigh(cov)
    return vecs[:, :, 0]


def _step(p: np.ndarray, n: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, bool]:
    """One linearised point-to-plane step for points ``p`` (M, 3) with target normals ``n`` and
    signed residuals ``r`` (M,): (rotation vector, translation) as (6,), and whether the geometry
    constrained every direction (unconstrained ones are left at zero)."""
    # robust (Cauchy) weights scaled by the residuals' MAD: surfaces that really changed between
    # the scenes stop pulling, while a genuine shift (all residuals alike) keeps full weight
    scale = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 0.005)
    wts = 1.0 / (1.0 + (r / (2.385 * scale)) ** 2)
    # rotation columns scaled by the sample's radius so that all six unknowns weigh alike
    L = max(float(np.sqrt((p**2).sum(axis=1).mean())), 1e-6)
    A = np.c_[np.cross(p, n) / L, n]
    H = A.T @ (A * wts[:, None])
    w, V = np.linalg.eigh(H)
    good = w > 1e-3 * max(w.max(), 1e-300)
    g = A.T @ -(wts * r)
    x = V[:, good] @ ((V[:, good].T @ g) / w[good])
    x[:3] /= L
    return x, bool(good.all())


def point_to_plane_icp(
    source: np.ndarray,
    target: np.ndarray,
    *,
    max_distance_m: float = 2.0,
    iterations: int = 30,
    trim: float = 0.9,
    tol_m: float = 1e-5,
) -> AlignmentCheck:
    """Rigid transform taking ``source`` (M, 3) onto ``target`` (N, 3), site-local float64 metres.

    Each iteration matches points within ``max_distance_m``, keeps the best ``trim`` fraction and
    solves the linearised point-to-plane problem; directions the geometry does not constrain (small
    eigenvalues) are left out, so a flat scene yields a finite answer flagged ``degenerate``.
    """
    src = np.asarray(source, dtype=np.float64)
    tgt = np.asarray(target, dtype=np.float64)
    if len(src) < 10 or len(tgt) < 10:
        return AlignmentCheck(
            float("inf"), 0.0, 0.0, Rigid("prev", "new", np.eye(3), np.zeros(3)), 0, True, 0
        )
    centre = tgt.mean(axis=0)
    src, tgt = src - centre, tgt - centre  # conditioning: rotations about the data, not the origin
    tree = cKDTree(tgt)
    normals = _normals(tree, tgt)
    T = np.eye(4)
    degenerate = False
    it = 0
    resid = np.zeros(0)
    for it in range(1, iterations + 1):  # noqa: B007  (the count is reported)
        moved = src @ T[:3, :3].T + T[:3, 3]
        d, j = tree.query(moved, distance_upper_bound=max_distance_m)
        ok = np.isfinite(d)
        if ok.sum() < 10:
            break
        p, q, n = moved[ok], tgt[j[ok]], normals[j[ok]]
        r = ((p - q) * n).sum(axis=1)
        x, constrained = _step(p, n, r)
        degenerate = degenerate or not constrained
        dT = np.eye(4)
        dT[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix()
        dT[:3, 3] = x[3:]
        T = dT @ T
        resid = r
        if np.linalg.norm(x) < tol_m:
            break
    moved = src @ T[:3, :3].T + T[:3, 3]
    d, j = tree.query(moved, distance_upper_bound=max_distance_m)
    ok = np.isfinite(d)
    if ok.sum():
        r = ((moved[ok] - tgt[j[ok]]) * normals[j[ok]]).sum(axis=1)
        r = r[np.abs(r) <= np.quantile(np.abs(r), trim)]
        resid = r
    # express the correction in the site-local frame (undo the centring)
    C = np.eye(4)
    C[:3, 3] = centre
    Ci = np.eye(4)
    Ci[:3, 3] = -centre
    T_site = C @ T @ Ci
    angle = float(np.degrees(Rotation.from_matrix(T[:3, :3]).magnitude()))
    return AlignmentCheck(
        residual_m=float(np.sqrt(np.mean(resid**2))) if resid.size else float("inf"),
        translation_m=float(np.linalg.norm(T[:3, 3])),
        rotation_deg=angle,
        prev_from_new=Rigid("prev", "new", Rotation.from_matrix(T_site[:3, :3]).as_matrix(), T_site[:3, 3]),
        matched=int(ok.sum()),
        degenerate=bool(degenerate),
        iterations=it,
    )
