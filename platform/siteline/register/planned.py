"""Cameras planned from a point cloud when a mission has no photos: a nadir survey grid over the
scene's area at a stated height above its ground, with oblique passes around its edge, in the
intrinsics of a named capture camera. Pure functions of a site-local sample of the scene's points
(no randomness): the same cloud and settings give the same cameras at any origin magnitude (poses
are snapped to the pose quanta)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from siteline.camera.intrinsics import Intrinsics
from siteline.camera.pinhole import Camera
from siteline.errors import RegistrationError
from siteline.records.registration import SurveyPlan
from siteline.tolerances import POSE_CENTER_QUANTUM_M, POSE_ROTATION_QUANTUM

# a camera is planned only over data: at least this many sample points under its image's centre area
MIN_POINTS_UNDER = 20
# the auto altitude's bounds (metres above the ground): DJI's terrain-following mapping flights start
# around 20 m, and 120 m is the ceiling of most drone regulations (EU open category, US Part 107's 400 ft)
MIN_AUTO_ALTITUDE_M = 20.0
MAX_AUTO_ALTITUDE_M = 120.0
# the auto altitude puts neighbouring points this many pixels apart in images of the release's auto
# scale (a 512 px long side, siteline.release.knobs.TARGET_LONG_SIDE_PX)
AUTO_SPACING_PX = 2.0
AUTO_LONG_SIDE_PX = 512
# and lowers the flight (more, smaller images) until the nadir grid holds at least this many
# cameras: each gives up to 32 candidate views, and about a third pass their probes
MIN_NADIR_CAMERAS = 16
# the tallest structure is found on a plan grid of this many metres: a cell's top is the 98th
# percentile of its kept points' heights (a jib or a roof, not a stray return), its ground the lowest
# 10th percentile of the cells within 12.5 m (under a roof the cell itself holds no ground), and a
# cell of fewer than 8 sample points (the survey sample holds 2-3 a square metre) says nothing
STRUCTURE_CELL_M = 5.0
STRUCTURE_TOP_PERCENTILE = 98.0
STRUCTURE_GROUND_CELLS = 2
MIN_STRUCTURE_POINTS = 8


@dataclass(frozen=True)
class Structure:
    """The tallest structure of a scene: its top's height above the ground under it (metres), where
    (the cell's centre, site-local metres) and the site class most of its top points have."""

    height_m: float
    xy: tuple[float, float]
    class_id: int

    def describe(self, class_name: str) -> str:
        """``the 18.8 m crane at (10, 5)``."""
        return f"the {self.height_m:.1f} m {class_name} at ({self.xy[0]:.0f}, {self.xy[1]:.0f})"


def tallest_structure(sample: np.ndarray, ignored: np.ndarray) -> Structure | None:
    """The highest kept surface above the ground under it (:data:`STRUCTURE_CELL_M` cells, see there)
    in a (N, 5) survey sample (site-local x, y, z, intensity, site class), its ``ignored`` (256,) bool
    classes (noise, snow, outside the fence) left out; None when no cell holds enough points."""
    pts = np.asarray(sample, np.float64)
    if pts.ndim != 2 or pts.shape[1] < 5 or not len(pts):
        return None
    pts = pts[~ignored[pts[:, 4].astype(np.int64)]]
    if not len(pts):
        return None
    ij = np.floor(pts[:, :2] / STRUCTURE_CELL_M).astype(np.int64)
    lo = ij.min(axis=0)
    shape = tuple(int(v) for v in ij.max(axis=0) - lo + 1)
    key = (ij[:, 0] - lo[0]) * shape[1] + (ij[:, 1] - lo[1])
    order = np.lexsort((pts[:, 2], key))
    keys, starts, counts = np.unique(key[order], return_index=True, return_counts=True)
    z = pts[order, 2]
    full = counts >= MIN_STRUCTURE_POINTS
    floor = np.full(shape[0] * shape[1], np.inf)
    top = np.full(shape[0] * shape[1], -np.inf)
    for k, s, n in zip(keys[full], starts[full], counts[full], strict=True):
        floor[k] = np.percentile(z[s : s + n], 10)
        top[k] = np.percentile(z[s : s + n], STRUCTURE_TOP_PERCENTILE)
    if not np.isfinite(top).any():
        return None
    from scipy.ndimage import minimum_filter

    size = 2 * STRUCTURE_GROUND_CELLS + 1
    ground = minimum_filter(floor.reshape(shape), size=size, mode="constant", cval=np.inf).ravel()
    height = np.where(np.isfinite(top) & np.isfinite(ground), top - ground, -np.inf)
    best = int(np.argmax(height))
    i, j = divmod(best, shape[1])
    xy = ((lo[0] + i + 0.5) * STRUCTURE_CELL_M, (lo[1] + j + 0.5) * STRUCTURE_CELL_M)
    cell = pts[key == best]
    high = cell[cell[:, 2] >= np.percentile(cell[:, 2], 90), 4].astype(np.int64)
    return Structure(float(height[best]), xy, int(np.bincount(high).argmax()))


def auto_altitude(
    plan: SurveyPlan, density_pts_m2: float, area_m2: float, tallest: tuple[Structure, str] | None = None
) -> tuple[float, str]:
    """The altitude (metres above the ground) planned cameras fly at when none is given, and why: at
    least the ``tallest`` structure's height (with its class's name) plus ``plan.clearance_m`` (a pilot
    flies over the crane, not under its jib), raised by the resolution rule only: the altitude that
    puts neighbouring points :data:`AUTO_SPACING_PX` apart in images of the release's auto scale
    (ground sample distance following the point spacing 1 / sqrt(density)), within
    [:data:`MIN_AUTO_ALTITUDE_M`, :data:`MAX_AUTO_ALTITUDE_M`], then lowered until the nadir grid over
    ``area_m2`` holds :data:`MIN_NADIR_CAMERAS` cameras (a small site is flown low, in more lines)."""
    model = plan.camera
    spacing = 1.0 / math.sqrt(max(density_pts_m2, 1e-9))
    f_release = min(model.fx, model.fy) * AUTO_LONG_SIDE_PX / max(model.width, model.height)
    wanted = spacing * f_release / AUTO_SPACING_PX
    h = min(MAX_AUTO_ALTITUDE_M, max(MIN_AUTO_ALTITUDE_M, wanted))
    why = (
        f"auto: {wanted:.0f} m puts points {spacing:.3f} m apart ({density_pts_m2:.3g} points/m2) "
        f"{AUTO_SPACING_PX:g} px apart at the release scale"
    )
    if h != wanted:
        why += f", held to {h:.0f} m (flights from {MIN_AUTO_ALTITUDE_M:.0f} to {MAX_AUTO_ALTITUDE_M:.0f} m)"
    if plan.nadir_cameras(h, area_m2) < MIN_NADIR_CAMERAS and h > MIN_AUTO_ALTITUDE_M:
        # cameras grow as 1 / altitude**2
        lower = max(MIN_AUTO_ALTITUDE_M, h * math.sqrt(plan.nadir_cameras(h, area_m2) / MIN_NADIR_CAMERAS))
        why += f"; lowered to {lower:.0f} m for at least {MIN_NADIR_CAMERAS} nadir cameras over {area_m2:,.0f} m2"
        h = lower
    if tallest is not None:
        structure, name = tallest
        clear = structure.height_m + plan.clearance_m
        if clear >= h:
            return float(round(clear, 1)), (
                f"auto: {clear:.1f} m clears {structure.describe(name)} by {plan.clearance_m:g} m (the resolution "
                f"rule asked for {h:.0f} m: {why.removeprefix('auto: ')})"
            )
        why += f"; it clears {structure.describe(name)} by {h - structure.height_m:.1f} m"
    return float(round(h, 1)), why


def _ground_z(sample: np.ndarray, xy: np.ndarray, radius_m: float) -> np.ndarray:
    """(K,) ground height under each (K, 2) position: the 10th percentile of the sample's z within
    ``radius_m`` (NaN where fewer than MIN_POINTS_UNDER sample points lie there)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(sample[:, :2])
    out = np.full(len(xy), np.nan)
    for k, near in enumerate(tree.query_ball_point(xy, radius_m)):
        if len(near) >= MIN_POINTS_UNDER:
            out[k] = float(np.percentile(sample[near, 2], 10))
    return out


def _snapped(cam: Camera) -> Camera:
    return cam.snapped(POSE_CENTER_QUANTUM_M, POSE_ROTATION_QUANTUM)


def _nadir(model: Intrinsics, center: np.ndarray) -> Camera:
    # looking straight down, image up to +y (north): image width along x, across the north-south lines
    target = center - np.array([0.0, 0.0, 1.0])
    return Camera.look_at(center, target, model.width, model.height, model.fx, model.fy, model.cx, model.cy)


def plan_cameras(sample: np.ndarray, area: list[tuple[float, float]], plan: SurveyPlan) -> dict[str, Camera]:
    """Survey cameras over ``area`` (a fence ring, site-local metres) from a (N, 3) site-local sample
    of the scene: north-south lines of nadir images at ``plan.altitude_m`` (set: :func:`auto_altitude`
    chooses it) above the local ground, spaced by the image footprint less the overlaps, kept where
    the image's centre area holds data, and an oblique camera at every other line position around
    the area's edge looking inward at ``plan.oblique_pitch_deg`` below the horizontal. Names:
    ``planned-nadir-NNNN``, ``planned-oblique-NNNN``. :class:`RegistrationError` when no camera lies
    over data."""
    if plan.altitude_m is None:
        raise RegistrationError("planned cameras: no altitude (choose one with auto_altitude).")
    pts = np.asarray(sample, dtype=np.float64)
    model, h = plan.camera, plan.altitude_m
    across, along = model.ground_footprint_m(h)  # image width along x, height along y
    dx, dy = across * (1.0 - plan.side_overlap), along * (1.0 - plan.forward_overlap)
    poly = shapely.Polygon(area)
    x0, y0, x1, y1 = poly.bounds
    xs = x0 + dx / 2.0 + dx * np.arange(max(1, math.ceil((x1 - x0) / dx)))
    ys = y0 + dy / 2.0 + dy * np.arange(max(1, math.ceil((y1 - y0) / dy)))
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    xy = np.c_[gx.ravel(), gy.ravel()]
    xy = xy[shapely.intersects_xy(poly.buffer(min(dx, dy) / 2.0), xy[:, 0], xy[:, 1])]
    cams: dict[str, Camera] = {}
    if len(pts) and len(xy):
        ground = _ground_z(pts, xy, min(dx, dy) / 2.0)
        for k in np.flatnonzero(np.isfinite(ground)):
            centre = np.array([xy[k, 0], xy[k, 1], ground[k] + h])
            cams[f"planned-nadir-{len(cams) + 1:04d}"] = _snapped(_nadir(model, centre))
    if not cams:
        raise RegistrationError(
            f"planned cameras: no survey position over the scene's data at {h:g} m (the area spans "
            f"{x1 - x0:.0f} x {y1 - y0:.0f} m); is the fence over the point cloud?"
        )
    if plan.oblique_pitch_deg > 0:
        cams |= _obliques(pts, poly, plan, 2.0 * min(dx, dy))
    return cams


def _obliques(pts: np.ndarray, poly: shapely.Polygon, plan: SurveyPlan, step_m: float) -> dict[str, Camera]:
    """Oblique cameras every ``step_m`` along the area's edge, each standing back from the edge so
    that it looks at the edge point at ``plan.oblique_pitch_deg``, aimed inward."""
    model, h = plan.camera, float(plan.altitude_m or 0.0)
    pitch = math.radians(plan.oblique_pitch_deg)
    back = h / math.tan(pitch)
    edge = poly.exterior
    stations = np.arange(0.0, edge.length, step_m)
    at = np.asarray(shapely.get_coordinates(edge.interpolate(stations)))
    centre = np.asarray(poly.representative_point().coords[0])
    ground = _ground_z(pts, at, step_m)
    out: dict[str, Camera] = {}
    for k in np.flatnonzero(np.isfinite(ground)):
        inward = centre - at[k]
        norm = float(np.hypot(*inward))
        if norm < 1e-6:
            continue
        inward /= norm
        eye = np.r_[at[k] - inward * back, ground[k] + h]
        target = np.r_[at[k], ground[k]]
        cam = Camera.look_at(eye, target, model.width, model.height, model.fx, model.fy, model.cx, model.cy)
        out[f"planned-oblique-{len(out) + 1:04d}"] = _snapped(cam)
    return out
