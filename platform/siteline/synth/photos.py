"""Synthetic DJI photos: a mapping mission's poses, renders without holes, drone-dji XMP and EXIF."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from datetime import datetime, timedelta

import numpy as np
import pyproj
from PIL import Image
from scipy.ndimage import distance_transform_edt

from siteline.camera.dji import cam_from_world_rotation, grid_convergence_deg
from siteline.camera.photos import dji_xmp, signed
from siteline.camera.pinhole import Camera
from siteline.records.params.render import RenderParams
from siteline.render.zbuffer import render_points

# Zenmuse L2 RGB sensor, full size; photos are written at a fraction of it
SENSOR_W, SENSOR_H = 5280, 3956
SENSOR_FX = 3520.0  # 24 mm equivalent: 73.7 degree horizontal field of view
SKY = np.array([200, 215, 235], np.uint8)


@dataclass(frozen=True)
class PhotoPose:
    """A photo's true pose: name, capture time, centre (site-local metres), DJI gimbal angles
    (degrees, yaw from true north), and the camera they give."""

    name: str
    time: datetime
    center_m: tuple[float, float, float]
    yaw_deg: float
    pitch_deg: float
    roll_deg: float
    camera: Camera


def photo_size(scale: float) -> tuple[int, int, float]:
    """(width, height, fx) of photos at ``scale`` of the sensor (round half up, as pycolmap)."""
    w = int(math.floor(SENSOR_W * scale + 0.5))
    h = int(math.floor(SENSOR_H * scale + 0.5))
    return w, h, SENSOR_FX * w / SENSOR_W


def mission_poses(
    start: datetime,
    scale: float,
    crs: pyproj.CRS,
    origin: tuple[float, float, float],
    altitude_m: float = 80.0,
) -> list[PhotoPose]:
    """A DJI mapping mission: nadir lawnmower lines at ``altitude_m`` plus an oblique orbit."""
    w, h, fx = photo_size(scale)
    to_geo = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    plan: list[tuple[tuple[float, float, float], float | None, float]] = []
    for k, y in enumerate((-40.0, 0.0, 40.0)):
        xs = (-60.0, -30.0, 0.0, 30.0, 60.0)
        for x in xs if k % 2 == 0 else xs[::-1]:
            plan.append(((x, y, altitude_m), 90.0 if k % 2 == 0 else -90.0, -90.0))
    for i in range(8):
        a = 2 * math.pi * i / 8
        c = (85.0 * math.cos(a), 85.0 * math.sin(a), 55.0)
        plan.append((c, None, -32.0))
    poses = []
    for i, (c, yaw, pitch) in enumerate(plan):
        lon, lat = to_geo.transform(origin[0] + c[0], origin[1] + c[1])
        conv = grid_convergence_deg(crs, lon, lat)
        if yaw is None:  # orbit: face the site centre (grid azimuth), written as a true-north yaw
            yaw = round(math.degrees(math.atan2(-c[0], -c[1])) - conv, 6)
        R = cam_from_world_rotation(yaw, pitch, 0.0, conv)
        C = np.asarray(c, dtype=np.float64)
        cam = Camera.from_pose(w, h, fx, fx, w / 2.0, h / 2.0, R, -R @ C)
        t = start + timedelta(seconds=2 * i)
        poses.append(PhotoPose(f"DJI_{t:%Y%m%d%H%M%S}_{i + 1:04d}_D.JPG", t, c, yaw, pitch, 0.0, cam))
    return poses


def render_photo(xyz: np.ndarray, rgb: np.ndarray, camera: Camera, spacing_m: float) -> np.ndarray:
    """(H, W, 3) uint8 photo of site-local float32 points: 3 px disks (1 px when the points are
    already denser than the pixels at the nadir distance) keep occlusion, remaining gaps are filled
    from the nearest hit, and regions with no point nearby are sky."""
    footprint = camera.center[2] / camera.fx
    k = 1 if spacing_m < footprint else 3
    r = render_points(xyz, camera, RenderParams(scale=1.0, point_size_px=k), {"rgb": rgb})
    dist, (iy, ix) = distance_transform_edt(~r.hit, return_indices=True)
    img = r.rgb[iy, ix]
    img[dist > 3 * k] = SKY
    return img


def photo_jpeg(
    img: np.ndarray, pose: PhotoPose, crs: pyproj.CRS, origin: tuple[float, float, float]
) -> bytes:
    """JPEG bytes with drone-dji XMP and EXIF DateTimeOriginal for a photo."""
    to_geo = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    x, y, z = (origin[i] + pose.center_m[i] for i in range(3))
    lon, lat = to_geo.transform(x, y)
    cam = pose.camera
    fields = {
        "Version": "1.2",
        "GpsStatus": "RTK",
        "AltitudeType": "RtkAlt",
        "GpsLatitude": signed(lat, 11),
        "GpsLongitude": signed(lon, 11),
        "AbsoluteAltitude": signed(z, 4),
        "RelativeAltitude": signed(pose.center_m[2], 4),
        "GimbalRollDegree": signed(pose.roll_deg, 8),
        "GimbalYawDegree": signed(pose.yaw_deg, 8),
        "GimbalPitchDegree": signed(pose.pitch_deg, 8),
        "FlightRollDegree": signed(0.0, 2),
        "FlightYawDegree": signed(pose.yaw_deg, 8),
        "FlightPitchDegree": signed(0.0, 2),
        "RtkFlag": "50",
        "RtkStdLon": "0.01214",
        "RtkStdLat": "0.01352",
        "RtkStdHgt": "0.02187",
        "CalibratedFocalLength": f"{cam.fx:.6f}",
        "CalibratedOpticalCenterX": f"{cam.cx:.6f}",
        "CalibratedOpticalCenterY": f"{cam.cy:.6f}",
        "DewarpData": f"{pose.time:%Y-%m-%d};{cam.fx:.6f},{cam.fy:.6f},0.000000,0.000000,0,0,0,0,0",
    }
    exif = Image.Exif()
    exif[0x010F] = "DJI"
    exif[0x0110] = "M350 RTK / Zenmuse L2"
    exif.get_ifd(0x8769)[0x9003] = f"{pose.time:%Y:%m:%d %H:%M:%S}"
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="JPEG", quality=90, exif=exif.tobytes(), xmp=dji_xmp(fields))
    return buf.getvalue()
