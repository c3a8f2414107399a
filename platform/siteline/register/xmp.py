"""Camera poses straight from DJI photo metadata (no reconstruction): RTK position and gimbal angles."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import pyproj

from siteline.camera.dji import cam_from_world_rotation, grid_convergence_deg
from siteline.camera.photos import PhotoMeta
from siteline.camera.pinhole import Camera, undistorted_pinhole
from siteline.errors import PhotoError

if TYPE_CHECKING:
    import pycolmap


def photo_center_crs(meta: PhotoMeta, crs: pyproj.CRS) -> np.ndarray:
    """Photo position (3,) float64 in ``crs``: WGS84 latitude/longitude and absolute (ellipsoidal)
    altitude, transformed in float64."""
    if not meta.has_position:
        raise PhotoError(f"photo {meta.file} has no position.")
    t = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    x, y = t.transform(meta.longitude_deg, meta.latitude_deg)
    out = np.array([x, y, meta.absolute_altitude_m], dtype=np.float64)
    if not np.isfinite(out).all():
        raise PhotoError(f"photo {meta.file}: its position cannot be expressed in {crs.name}.")
    return out


def dewarp_camera(meta: PhotoMeta) -> pycolmap.Camera | None:
    """The distorted pycolmap camera DJI's ``DewarpData`` describes (FULL_OPENCV: fx, fy, principal
    point = image centre + the cx, cy offsets, k1, k2, p1, p2, k3), or None when the photo has no
    DewarpData or all its distortion coefficients are zero."""
    import pycolmap

    d = meta.dewarp
    if d is None or meta.width is None or meta.height is None:
        return None
    if len(d) != 9:
        raise PhotoError(
            f"photo {meta.file}: DewarpData has {len(d)} numbers, expected 9 (fx,fy,cx,cy,k1,k2,p1,p2,k3)."
        )
    fx, fy, dcx, dcy, k1, k2, p1, p2, k3 = d
    if not any((k1, k2, p1, p2, k3)):
        return None
    return pycolmap.Camera(
        model="FULL_OPENCV",
        width=meta.width,
        height=meta.height,
        params=[fx, fy, meta.width / 2.0 + dcx, meta.height / 2.0 + dcy, k1, k2, p1, p2, k3, 0.0, 0.0, 0.0],
    )


def dewarp_pinhole(meta: PhotoMeta) -> pycolmap.Camera | None:
    """The undistorted pinhole of :func:`dewarp_camera` (the camera a COLMAP model with the same
    distortion gives), or None."""
    cam = dewarp_camera(meta)
    return undistorted_pinhole(cam) if cam is not None else None


def camera_from_photo(meta: PhotoMeta, crs: pyproj.CRS, origin: Sequence[float]) -> Camera:
    """The photo's pinhole camera in the site-local frame of ``origin`` (float64, ``crs`` units).

    Intrinsics come from ``DewarpData`` when it carries distortion (its undistorted pinhole, as for a
    COLMAP model), else from CalibratedFocalLength / CalibratedOpticalCenterX/Y and the image size;
    orientation from the gimbal angles, yaw corrected by the grid convergence at the photo.
    """
    yaw, pitch = meta.gimbal_yaw_deg, meta.gimbal_pitch_deg
    if not meta.has_orientation or yaw is None or pitch is None:
        raise PhotoError(f"photo {meta.file} has no gimbal angles (GimbalYawDegree, GimbalPitchDegree).")
    if meta.longitude_deg is None or meta.latitude_deg is None:
        raise PhotoError(f"photo {meta.file} has no position (GpsLatitude, GpsLongitude).")
    if meta.width is None or meta.height is None:
        raise PhotoError(f"photo {meta.file}: image size unknown.")
    fx = meta.calibrated_focal_length_px
    if fx is None:
        raise PhotoError(f"photo {meta.file} has no CalibratedFocalLength: intrinsics unknown.")
    cx = (
        meta.calibrated_optical_center_x_px
        if meta.calibrated_optical_center_x_px is not None
        else meta.width / 2.0
    )
    cy = (
        meta.calibrated_optical_center_y_px
        if meta.calibrated_optical_center_y_px is not None
        else meta.height / 2.0
    )
    center = photo_center_crs(meta, crs) - np.asarray(origin, dtype=np.float64)
    dewarped = dewarp_pinhole(meta)
    if dewarped is not None:
        w, h = int(dewarped.width), int(dewarped.height)
        fx, fy, cx, cy = (float(v) for v in dewarped.params)
        conv = grid_convergence_deg(crs, meta.longitude_deg, meta.latitude_deg)
        R = cam_from_world_rotation(yaw, pitch, meta.gimbal_roll_deg or 0.0, conv)
        return Camera.from_pose(w, h, fx, fy, cx, cy, R, -R @ center)
    conv = grid_convergence_deg(crs, meta.longitude_deg, meta.latitude_deg)
    R = cam_from_world_rotation(yaw, pitch, meta.gimbal_roll_deg or 0.0, conv)
    return Camera.from_pose(meta.width, meta.height, fx, fx, cx, cy, R, -R @ center)
