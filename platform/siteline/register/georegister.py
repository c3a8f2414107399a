"""Georegistration of a mission's COLMAP model: a Sim3 to the photos' RTK positions (pycolmap)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from siteline.camera.pinhole import Camera, CameraModel, distortion_model
from siteline.camera.poses import Sim3
from siteline.errors import RegistrationError
from siteline.records.registration import Registration


@dataclass
class Georegistration:
    """``site_from_model``: the Sim3 from the COLMAP model's frame to the site-local frame (metres), and
    the per-image residuals: distance in metres between each registered camera centre and its RTK
    position (site-local)."""

    site_from_model: Sim3
    camera_models: dict[str, CameraModel]
    residuals_m: dict[str, float]
    cameras: dict[str, Camera]

    @property
    def rms_m(self) -> float:
        r = np.array(list(self.residuals_m.values()))
        return float(np.sqrt(np.mean(r**2))) if r.size else float("nan")

    def record(self) -> Registration:
        """The scene's registration record of it."""
        return Registration(
            "colmap",
            images=len(self.residuals_m),
            camera_models=self.camera_models,
            residuals_m=self.residuals_m,
            rms_m=self.rms_m,
            site_from_model=self.site_from_model,
        )


def check_spread(names: list[str], locations: np.ndarray, where: str, min_images: int = 3) -> None:
    """Refuse fewer than ``min_images`` positions, or positions on a line (a Sim3 is then undefined)."""
    if len(names) < min_images:
        raise RegistrationError(
            f"{where}: only {len(names)} images have both a pose in the COLMAP model and a "
            f"position in their metadata; georegistration needs at least {min_images}."
        )
    centred = locations - locations.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv[0] == 0 or sv[1] < 1e-3 * sv[0] or sv[1] < 0.05:
        raise RegistrationError(
            f"{where}: the {len(names)} photo positions are collinear (or coincide); a Sim3 "
            "cannot be fitted to them."
        )


def georegister(
    model_dir: Path,
    locations_m: Mapping[str, np.ndarray],
    *,
    max_error_m: float = 0.5,
    max_rms_m: float = 0.1,
    min_images: int = 3,
) -> Georegistration:
    """Align the COLMAP model in ``model_dir`` to site-local photo positions (name -> (3,) float64).

    Raises :class:`RegistrationError` when the model is unreadable, too few images match, the
    positions are degenerate, pycolmap finds no alignment, or the RMS residual exceeds ``max_rms_m``.
    """
    import pycolmap

    try:
        rec = pycolmap.Reconstruction(str(model_dir))
    except Exception as exc:
        raise RegistrationError(f"COLMAP model {model_dir} cannot be read: {exc}") from exc
    names, locs = [], []
    for img in rec.images.values():
        if img.has_pose and img.name in locations_m:
            names.append(img.name)
            locs.append(np.asarray(locations_m[img.name], dtype=np.float64))
    loc_arr = np.array(locs).reshape(-1, 3)
    check_spread(names, loc_arr, f"COLMAP model {model_dir}", min_images)
    opts = pycolmap.RANSACOptions()
    opts.max_error = max_error_m
    sim = pycolmap.align_reconstruction_to_locations(rec, names, loc_arr, min_images, opts)
    if sim is None:
        raise RegistrationError(
            f"COLMAP model {model_dir}: no similarity maps the model onto the photo positions "
            f"within {max_error_m} m (RANSAC failed)."
        )
    rec.transform(sim)
    residuals, cameras = {}, {}
    for img in rec.images.values():
        if not img.has_pose:
            continue
        cam = Camera.from_pycolmap(img.camera, img.cam_from_world())
        cameras[img.name] = cam
        if img.name in locations_m:
            residuals[img.name] = float(np.linalg.norm(cam.center - np.asarray(locations_m[img.name])))
    site_from_model = Sim3(
        "site", "model", float(sim.scale), np.asarray(sim.rotation.matrix()), np.asarray(sim.translation)
    )
    models = {}
    for cam_id, cam in rec.cameras.items():
        record = distortion_model(cam)
        if record is not None:
            models[str(cam_id)] = record
    result = Georegistration(site_from_model, models, residuals, cameras)
    if not np.isfinite(result.rms_m) or result.rms_m > max_rms_m:
        worst = max(residuals, key=lambda name: residuals[name])
        raise RegistrationError(
            f"COLMAP model {model_dir}: georegistration RMS {result.rms_m:.3f} m exceeds "
            f"{max_rms_m} m (worst: {worst} at {residuals[worst]:.3f} m)."
        )
    return result
