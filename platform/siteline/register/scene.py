"""Scene registration, the stage's entry points: real camera poses for a mission's photos, and the
check that a new scene lines up with the previous one (DESIGN.md §3)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import shapely

from siteline.camera.photos import PhotoMeta
from siteline.camera.pinhole import Camera, distortion_model
from siteline.errors import RegistrationError
from siteline.records.enums import CameraSource
from siteline.records.registration import Alignment, Registration, SurveyPlan
from siteline.records.scan import SAMPLE_STABLE, SAMPLE_STRUCTURE
from siteline.register.georegister import georegister
from siteline.register.icp import register_samples
from siteline.register.planned import auto_altitude, plan_cameras, tallest_structure
from siteline.register.xmp import camera_from_photo, dewarp_camera, photo_center_crs
from siteline.site.spec import SiteSpec


@dataclass(frozen=True)
class AlignmentPolicy:
    """How a new scene is co-registered onto the previous one by ICP on their stable surfaces: the
    correction is applied when it moves the scene by more than ``apply_above_m`` (construction
    changes between epochs bias ICP by up to 0.16 m on the synthetic site, whose epochs are truly
    aligned: smaller corrections are recorded, not applied) and at most ``max_translation_m`` (a
    larger offset means a wrong CRS or datum: ICP's capture range, measured on a real airborne
    cloud, ends between 2.5 m (found to 2 mm) and 5 m (0.4 m off)); the residual on stable surfaces
    (m) and the share of stable points that overlap the previous scene must be within bounds."""

    max_translation_m: float = 3.0
    max_residual_m: float = 0.15
    min_overlap: float = 0.2
    apply_above_m: float = 0.25


def register_cameras(
    photos: dict[str, PhotoMeta],
    model: Path | None,
    spec: SiteSpec,
    ransac_max_error_m: float,
    max_rms_m: float,
) -> tuple[dict[str, Camera], Registration, CameraSource | None]:
    """Cameras by image name (site-local), the registration record, and the camera source: a COLMAP
    model georegistered by a Sim3 to the photos' RTK positions, else the photos' XMP poses."""
    if not photos:
        return {}, Registration("none", note="LiDAR-only mission: no photos"), None
    crs = spec.pyproj_crs
    origin = np.asarray(spec.origin, dtype=np.float64)
    by_name = {Path(p).name: m for p, m in photos.items()}
    if model is not None:
        locations = {name: photo_center_crs(m, crs) - origin for name, m in by_name.items()}
        reg = georegister(model, locations, max_error_m=ransac_max_error_m, max_rms_m=max_rms_m)
        return reg.cameras, reg.record(), "colmap"
    cams = {name: camera_from_photo(m, crs, spec.origin) for name, m in by_name.items()}
    models = {name: distortion_model(c) for name, m in by_name.items() if (c := dewarp_camera(m)) is not None}
    # the DewarpData distortion each undistorted camera came from
    return cams, Registration("xmp", images=len(cams), camera_models=models or None), "xmp"


def planned_cameras(
    sample: np.ndarray,
    footprint: list[list[float]] | None,
    spec: SiteSpec,
    survey: SurveyPlan,
    photos: int,
    density_pts_m2: float,
) -> tuple[dict[str, Camera], Registration, CameraSource | None]:
    """Cameras planned over the site's fence, or the scene's footprint when the site has none, from
    the scene's (N, 3+) site-local sample at an altitude chosen from its ``density_pts_m2`` and area
    unless ``survey`` sets one; the registration record says how and why (``photos``: how many
    photos the mission had, which the planned cameras replace). A scene no survey can be planned
    over (its points span no area, or no camera position lies over them) gets no cameras, and the
    record says why (a release then refuses its pairs, naming the scene): it is still a scene."""
    note = "cameras planned from the point cloud" + (
        f" ({photos} photos not used)" if photos else " (LiDAR-only mission: no photos)"
    )
    if spec.fence is not None:
        area, where = [(float(x), float(y)) for x, y in spec.fence], "site fence"
    elif footprint is not None:
        area, where = [(float(x), float(y)) for x, y in footprint], "scene footprint"
    else:
        why = "its points span no area (they lie on a line or a point) and the site has no fence"
        return {}, Registration("none", planned=False, note=f"no cameras could be planned: {why}"), None
    area_m2 = float(shapely.Polygon(area).area)
    found = tallest_structure(sample, spec.taxonomy.ignored_lut())
    tallest = None if found is None else (found, spec.taxonomy.name_of(found.class_id))
    altitude_why = "given (--altitude)"
    if survey.altitude_m is None:
        altitude, altitude_why = auto_altitude(survey, density_pts_m2, area_m2, tallest)
        survey = replace(survey, altitude_m=altitude)
    elif tallest is not None and survey.altitude_m < tallest[0].height_m:
        raise RegistrationError(
            f"planned cameras: --altitude {survey.altitude_m:g} m flies under {tallest[0].describe(tallest[1])} "
            f"(site-local metres, above the ground under it): give at least {tallest[0].height_m + survey.clearance_m:.0f} m "
            f"(its height and the {survey.clearance_m:g} m clearance), or leave --altitude out to have it chosen"
        )
    record = Registration("planned", note=note, over=where, survey=survey, altitude_why=altitude_why)
    try:
        cams = plan_cameras(sample[:, :3], area, survey)
    except RegistrationError as exc:
        return {}, replace(record, source="none", planned=False, images=0, note=f"no cameras: {exc}"), None
    return cams, replace(record, images=len(cams)), "planned"


def check_alignment(
    sample_new: np.ndarray,
    sample_previous: np.ndarray,
    previous_scene: int,
    mission: str,
    policy: AlignmentPolicy,
    accept_misalignment: bool = False,
) -> Alignment:
    """Align the new scene's co-registration sample ((N, 4) site-local metres and kind of surface;
    siteline.ingest.pointcloud; an (N, 3) sample of an older scene is all stable surfaces) onto the
    previous scene's, direction by direction (siteline.register.icp.register_samples); return the
    record: the correction (``prev_from_new``, 4 x 4), what fixed each direction, the residuals, and
    ``applied`` when ingest is to apply it (over ``policy.apply_above_m``). :class:`RegistrationError`
    when it breaks ``policy`` and not ``accept_misalignment`` (a registration accepted so is
    recorded, not applied). Directions nothing fixes are never moved; the record names them."""
    new_stable, new_structure = _kinds(sample_new)
    old_stable, old_structure = _kinds(sample_previous)
    check = register_samples(new_stable, old_stable, new_structure, old_structure)
    overlap = check.matched / max(
        len(new_stable) if check.surfaces == "ground and building" else len(sample_new), 1
    )
    bad = (
        check.translation_m > policy.max_translation_m
        or overlap < policy.min_overlap
        or not np.isfinite(check.residual_m)
        or check.residual_m > policy.max_residual_m
    )
    record = Alignment(
        previous_scene, check.translation_m, check.rotation_deg,
        applied=bool(not bad and check.translation_m > policy.apply_above_m), residual_m=check.residual_m,
        residual_xy_m=check.residual_xy_m, axes=dict(check.axes),
        correction=tuple(tuple(row) for row in check.correction), accepted=not bad or accept_misalignment,
        residual_z_m=check.residual_z_m, correction_frames=check.prev_from_new.name, matched=check.matched,
        structure_matched=check.structure_matched, surfaces=check.surfaces, degenerate=check.degenerate,
        iterations=check.iterations, overlap=overlap, apply_above_m=policy.apply_above_m,
    )  # fmt: skip
    if bad and not accept_misalignment:
        raise RegistrationError(
            f"mission {mission} cannot be co-registered with scene {previous_scene}: ICP on {check.surfaces} "
            f"moves it by {check.translation_m:.3f} m (at most {policy.max_translation_m} m is corrected: more "
            f"means a wrong CRS or datum) with residual {check.residual_m:.3f} m (limit {policy.max_residual_m} m), "
            f"{overlap:.0%} of its stable points overlap the previous scene (at least {policy.min_overlap:.0%} "
            "needed). Check the CRS and the georeferencing, or pass --accept-misalignment to register it "
            "uncorrected. Nothing was ingested."
        )
    return record


def _kinds(sample: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(stable surfaces, structure) points (M, 3) of a co-registration sample."""
    pts = np.asarray(sample, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 4:
        return pts.reshape(-1, 3), np.zeros((0, 3))
    return pts[pts[:, 3] == SAMPLE_STABLE, :3], pts[pts[:, 3] == SAMPLE_STRUCTURE, :3]
