"""Co-registering two scenes' samples direction by direction (DESIGN.md §2): point-to-plane ICP on
the stable surfaces (ground and buildings) fixes what they can (on flat ground: height, roll, pitch),
then point-to-point ICP on the scene's structure of any kept class (trunks, canopy, walls, poles,
unclassified points) solves the directions the first left free, with robust weights so that what
changed between the scenes stops pulling. Each direction is reported as fixed by the surfaces, by
the structure, or not at all; a free direction is never moved and never claimed."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from siteline.camera.poses import Rigid
from siteline.records.registration import AXES  # the solver's unknowns, in this order

SURFACES = "ground and building surfaces"
STRUCTURE = "structure of any kept class"
# a direction counts as fixed when its eigenvalue of the normal equations (rotations scaled to the
# sample's radius) is at least this share of the largest: the random tilt of flat ground's normals
# gives its free directions about 2e-4 at a metre's spacing; a building's walls give 1e-3 and more
_FIXED_SHARE = 5e-4
# the fewest matched points a stage solves from
_MIN_POINTS = 30
# the structure fixes yaw only when its points spread horizontally (RMS about their own centre) over at
# least this share of the sample's radius: one tree (a 3 m crown on a 100 m site: 0.03) turns the
# scene about itself as freely as it shifts it, and its leaves, other leaves each flight, turned a
# flown box scene by 7.8 degrees (5.6 m at the site's edge); trees along two sides spread over 0.5
_YAW_SPREAD_SHARE = 0.2
_YAW = 2  # AXES: roll, pitch, yaw, x, y, z


@dataclass
class AlignmentCheck:
    """Result of aligning a new scene's sample onto the previous scene's.

    residual_m: RMS point-to-plane distance of the matched stable points after alignment (what a
    height offset shows). residual_xy_m / residual_z_m: RMS of the horizontal and vertical parts of
    the point-to-point distances of the structure points after alignment (what a horizontal offset
    cannot hide; None where no structure was matched; its floor is about half the point spacing).
    translation_m, rotation_deg: the rigid correction found (what the new scene is off by).
    prev_from_new: that correction as a pose, site-local metres of the new scene -> the previous one.
    matched: matched stable point pairs. axes: per direction (roll, pitch, yaw, x, y, z) what fixed
    it (:data:`SURFACES`, :data:`STRUCTURE`) or None when nothing did (left at zero).
    degenerate: some direction stayed free.
    """

    residual_m: float
    translation_m: float
    rotation_deg: float
    prev_from_new: Rigid
    matched: int
    degenerate: bool
    iterations: int
    axes: dict[str, str | None] = field(default_factory=dict)
    residual_xy_m: float | None = None
    residual_z_m: float | None = None
    structure_matched: int = 0
    surfaces: str = "ground and building"

    @property
    def correction(self) -> list[list[float]]:
        """``prev_from_new`` as a (4, 4) homogeneous matrix (nested lists)."""
        return self.prev_from_new.matrix().tolist()

    @property
    def free(self) -> list[str]:
        """The directions nothing fixed."""
        return [a for a in AXES if self.axes.get(a) is None]


def _normals(tree: cKDTree, pts: np.ndarray, k: int = 24) -> np.ndarray:
    _, idx = tree.query(pts, k=min(k, len(pts)), workers=-1)
    nb = pts[idx] - pts[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)
    _, vecs = np.linalg.eigh(cov)
    return vecs[:, :, 0]


def _noise(r: np.ndarray) -> float:
    """The residuals' robust scale (1.4826 MAD, metres), at least 5 mm."""
    return max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 0.005)


def _robust(r: np.ndarray) -> np.ndarray:
    """Cauchy weights of residuals ``r`` (M,) scaled by their MAD: surfaces that really changed between
    the scenes stop pulling, while a genuine shift (all residuals alike) keeps full weight."""
    return 1.0 / (1.0 + (r / (2.385 * _noise(r))) ** 2)


def _solve(H: np.ndarray, g: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """The step ``x`` (6,) within the span of ``basis`` (6, k) solving ``H x = g`` (directions the
    normal equations leave numerically singular stay at zero)."""
    if basis.shape[1] == 0:
        return np.zeros(6)
    w, V = np.linalg.eigh(basis.T @ H @ basis)
    good = w > 1e-9 * max(float(w.max()), 1e-300)
    return basis @ (V[:, good] @ ((V[:, good].T @ (basis.T @ g)) / w[good]))


def _apply(T: np.ndarray, x: np.ndarray, scale: float) -> np.ndarray:
    dT = np.eye(4)
    dT[:3, :3] = Rotation.from_rotvec(x[:3] / scale).as_matrix()
    dT[:3, 3] = x[3:]
    return dT @ T


def _params(T: np.ndarray, scale: float) -> np.ndarray:
    """(6,) the unknowns of ``T``: rotation vector times ``scale``, translation."""
    return np.r_[Rotation.from_matrix(T[:3, :3]).as_rotvec() * scale, T[:3, 3]]


def _moved(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:3, :3].T + T[:3, 3]


class _Fit:
    """One kind of ICP between two centred clouds: point-to-plane (the target's normals) or
    point-to-point, run from a pose and within a subspace of the six unknowns."""

    def __init__(
        self, src: np.ndarray, tgt: np.ndarray, scale: float, planes: bool, max_distance_m: float
    ) -> None:
        self.src, self.tgt, self.scale, self.planes, self.reach = src, tgt, scale, planes, max_distance_m
        self.tree = cKDTree(tgt)
        self.normals = _normals(self.tree, tgt) if planes else None

    def residuals(
        self, T: np.ndarray, src: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None] | None:
        """(moved points that matched, their residuals: signed distances along the target's normals or
        offset vectors, which matched, the normals matched), None when too few matched."""
        moved = _moved(T, src)
        d, j = self.tree.query(moved, distance_upper_bound=self.reach, workers=-1)
        ok = np.isfinite(d)
        if ok.sum() < _MIN_POINTS:
            return None
        p, q = moved[ok], self.tgt[j[ok]]
        if self.normals is not None:
            n = self.normals[j[ok]]
            return p, ((p - q) * n).sum(axis=1), ok, n
        return p, p - q, ok, None

    def run(
        self, T: np.ndarray, basis: np.ndarray, iterations: int, src: np.ndarray | None = None
    ) -> tuple[np.ndarray, int]:
        """``T`` improved by up to ``iterations`` steps within the span of ``basis`` (6, k); the steps taken."""
        src = self.src if src is None else src
        it = 0
        for it in range(1, iterations + 1):  # noqa: B007  (the count is reported)
            found = self.residuals(T, src)
            if found is None:
                break
            p, r, _, n = found
            if n is not None:
                A = np.c_[np.cross(p, n) / self.scale, n]
                wts = _robust(r)
                H, g = A.T @ (A * wts[:, None]), A.T @ -(wts * r)
            else:
                wts = _robust(np.linalg.norm(r, axis=1))
                # d(p')/d(rotation, translation) = [-[p]_x / scale, I] for each of the three coordinates
                J = np.zeros((len(p), 3, 6))
                J[:, :, :3] = -_skew(p) / self.scale
                J[:, :, 3:] = np.eye(3)
                H = np.einsum("n,nki,nkj->ij", wts, J, J)
                g = -np.einsum("n,nki,nk->i", wts, J, r)
            x = _solve(H, g, basis)
            T = _apply(T, x, self.scale)
            if np.linalg.norm(x) < 1e-4:  # a tenth of a millimetre
                break
        return T, it

    def fixes(self, T: np.ndarray, axes: list[int]) -> list[int]:
        """Which of ``axes`` the matches at ``T`` fix: those lying mostly in the span of the eigen-
        directions of the normal equations (within ``axes``) whose eigenvalue is at least
        :data:`_FIXED_SHARE` of the largest."""
        found = self.residuals(T, self.src)
        if found is None or not axes:
            return []
        p, r, _, n = found
        if n is not None:
            A = np.c_[np.cross(p, n) / self.scale, n]
            H = A.T @ (A * _robust(r)[:, None])
        else:
            J = np.zeros((len(p), 3, 6))
            J[:, :, :3] = -_skew(p) / self.scale
            J[:, :, 3:] = np.eye(3)
            H = np.einsum("n,nki,nkj->ij", _robust(np.linalg.norm(r, axis=1)), J, J)
        basis = _axes_basis(axes)
        w, V = np.linalg.eigh(basis.T @ H @ basis)
        span = basis @ V[:, w >= _FIXED_SHARE * max(float(w.max()), 1e-300)]
        return [a for a in axes if np.linalg.norm(span[a]) > 0.7]


def _skew(p: np.ndarray) -> np.ndarray:
    """(M, 3, 3) cross-product matrices of (M, 3) vectors."""
    out = np.zeros((len(p), 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -p[:, 2], p[:, 1]
    out[:, 1, 0], out[:, 1, 2] = p[:, 2], -p[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -p[:, 1], p[:, 0]
    return out


def _axes_basis(axes: list[int]) -> np.ndarray:
    """(6, k) the unit unknowns of ``axes``."""
    return np.eye(6)[:, sorted(axes)]


def _point_residuals(
    src: np.ndarray, tgt: np.ndarray, T: np.ndarray, max_distance_m: float
) -> tuple[float | None, float | None, int]:
    """RMS of the horizontal and vertical parts of the trimmed nearest-point distances of ``src``
    moved by ``T`` to ``tgt``, and how many matched."""
    if len(src) < _MIN_POINTS or len(tgt) < _MIN_POINTS:
        return None, None, 0
    d, j = cKDTree(tgt).query(_moved(T, src), distance_upper_bound=max_distance_m)
    ok = np.isfinite(d)
    if ok.sum() < _MIN_POINTS:
        return None, None, int(ok.sum())
    e = _moved(T, src[ok]) - tgt[j[ok]]
    keep = d[ok] <= np.quantile(d[ok], 0.9)
    e = e[keep]
    return (
        float(np.sqrt((e[:, :2] ** 2).sum(axis=1).mean())),
        float(np.sqrt((e[:, 2] ** 2).mean())),
        int(ok.sum()),
    )


def _samples(
    source: np.ndarray,
    target: np.ndarray,
    source_structure: np.ndarray | None,
    target_structure: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """The samples as (M, 3) float64 arrays (surfaces, then structure; none given: empty) and which
    surfaces the fit uses: with too few ground and building points, every kept point takes their part."""

    def rows(a: np.ndarray | None) -> np.ndarray:
        return np.asarray(a if a is not None else np.zeros((0, 3)), np.float64).reshape(-1, 3)

    src, tgt, s_src, s_tgt = rows(source), rows(target), rows(source_structure), rows(target_structure)
    few = len(src) < _MIN_POINTS or len(tgt) < _MIN_POINTS
    if few and len(s_src) >= _MIN_POINTS and len(s_tgt) >= _MIN_POINTS:
        return np.r_[src, s_src], np.r_[tgt, s_tgt], s_src, s_tgt, "every kept class (no ground or building)"
    return src, tgt, s_src, s_tgt, "ground and building"


def register_samples(
    source: np.ndarray,
    target: np.ndarray,
    source_structure: np.ndarray | None = None,
    target_structure: np.ndarray | None = None,
    *,
    max_distance_m: float = 2.0,
    iterations: int = 30,
) -> AlignmentCheck:
    """The rigid correction taking the new scene onto the previous one, site-local float64 metres:
    ``source`` / ``target`` (M, 3) / (N, 3) their stable surfaces (ground and buildings), and
    ``*_structure`` the rest of their kept points (any other class that does not come and go), which
    fix what the surfaces leave free. With too few stable points, every point takes the surfaces'
    part. Directions nothing fixes are left at zero and reported free (``axes``)."""
    src, tgt, s_src, s_tgt, surfaces = _samples(source, target, source_structure, target_structure)
    if len(src) < 10 or len(tgt) < 10:
        return AlignmentCheck(
            float("inf"), 0.0, 0.0, Rigid("prev", "new", np.eye(3), np.zeros(3)), 0, True, 0,
            dict.fromkeys(AXES), surfaces=surfaces,
        )  # fmt: skip
    centre = tgt.mean(axis=0)
    src, tgt, s_src, s_tgt = src - centre, tgt - centre, s_src - centre, s_tgt - centre
    # rotations scaled by the sample's radius, so that all six unknowns weigh alike
    scale = max(float(np.sqrt((tgt**2).sum(axis=1).mean())), 1e-6)
    surface = _Fit(src, tgt, scale, True, max_distance_m)
    T, it = surface.run(np.eye(4), np.eye(6), iterations)
    by_surfaces = surface.fixes(T, list(range(6)))
    if len(by_surfaces) < 6:  # solve again moving only what the surfaces fix: a free direction stays at zero
        T, it = surface.run(np.eye(4), _axes_basis(by_surfaces), iterations)
    free = [k for k in range(6) if k not in by_surfaces]
    by_structure: list[int] = []
    if free and len(s_src) >= _MIN_POINTS and len(s_tgt) >= _MIN_POINTS:
        structure = _Fit(s_src, s_tgt, scale, False, max_distance_m)
        moved, _ = structure.run(T, _axes_basis(free), 40)
        by_structure = structure.fixes(moved, free)
        spread = float(np.sqrt(((s_tgt[:, :2] - s_tgt[:, :2].mean(axis=0)) ** 2).sum(axis=1).mean()))
        if _YAW in by_structure and spread < _YAW_SPREAD_SHARE * scale:
            by_structure.remove(_YAW)
        if by_structure:
            T, _ = structure.run(T, _axes_basis(by_structure), 40)
    axes = {
        a: SURFACES if k in by_surfaces else STRUCTURE if k in by_structure else None
        for k, a in enumerate(AXES)
    }
    found = surface.residuals(T, src)
    resid = np.zeros(0)
    matched = 0
    if found is not None:
        r = found[1]
        resid = r[np.abs(r) <= np.quantile(np.abs(r), 0.9)]
        matched = int(found[2].sum())
    rxy, rz, s_matched = _point_residuals(s_src, s_tgt, T, max_distance_m)
    C, Ci = np.eye(4), np.eye(4)
    C[:3, 3], Ci[:3, 3] = centre, -centre
    T_site = C @ T @ Ci
    return AlignmentCheck(
        residual_m=float(np.sqrt(np.mean(resid**2))) if resid.size else float("inf"),
        translation_m=float(np.linalg.norm(T[:3, 3])),
        rotation_deg=float(np.degrees(Rotation.from_matrix(T[:3, :3]).magnitude())),
        prev_from_new=Rigid("prev", "new", Rotation.from_matrix(T_site[:3, :3]).as_matrix(), T_site[:3, 3]),
        matched=matched,
        degenerate=any(v is None for v in axes.values()),
        iterations=it,
        axes=axes,
        residual_xy_m=rxy,
        residual_z_m=rz,
        structure_matched=s_matched,
        surfaces=surfaces,
    )


def point_to_plane_icp(
    source: np.ndarray, target: np.ndarray, *, max_distance_m: float = 2.0, iterations: int = 30
) -> AlignmentCheck:
    """Point-to-plane ICP of ``source`` (M, 3) onto ``target`` (N, 3) alone (no structure): a flat
    scene yields a finite answer whose free directions stay at zero, flagged ``degenerate``."""
    return register_samples(source, target, max_distance_m=max_distance_m, iterations=iterations)
