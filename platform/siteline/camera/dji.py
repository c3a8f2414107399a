"""DJI conventions (DESIGN.md §9.2): gimbal angles <-> camera rotations, grid convergence.

DJI gives gimbal yaw, pitch and roll in degrees in the local NED frame (true north), intrinsic Z-Y-X.
Pitch -90 is nadir; with yaw 0 and pitch -90 the image top points north. siteline's world is the
site-local frame of a projected CRS (x east, y north, z up, grid north), so yaw is corrected by the
grid convergence (the grid azimuth of true north) at the camera.
"""

from __future__ import annotations

import math

import numpy as np
import pyproj

# camera axes (x right, y down, z forward) expressed in the gimbal body frame (x forward, y right, z down)
_BODY_FROM_CAM = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
# ENU from NED
_ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def cam_from_world_rotation(
    yaw_deg: float, pitch_deg: float, roll_deg: float, convergence_deg: float = 0.0
) -> np.ndarray:
    """cam_from_world rotation (3, 3) of a camera with DJI gimbal angles (degrees, yaw from true north)
    in a grid frame (x east, y grid north, z up); ``convergence_deg`` is the grid azimuth of true north
    at the camera (:func:`grid_convergence_deg`)."""
    yaw = math.radians(yaw_deg + convergence_deg)
    ned_from_body = _rz(yaw) @ _ry(math.radians(pitch_deg)) @ _rx(math.radians(roll_deg))
    world_from_cam = _ENU_FROM_NED @ ned_from_body @ _BODY_FROM_CAM
    return world_from_cam.T


def gimbal_angles(cam_from_world: np.ndarray, convergence_deg: float = 0.0) -> tuple[float, float, float]:
    """(yaw, pitch, roll) degrees, true-north yaw, of a cam_from_world rotation (inverse of
    :func:`cam_from_world_rotation`). At pitch -90 yaw and roll are not separable: roll is set to 0."""
    world_from_cam = np.asarray(cam_from_world, dtype=np.float64).T
    ned_from_body = _ENU_FROM_NED.T @ world_from_cam @ _BODY_FROM_CAM.T
    # ned_from_body = Rz(yaw) Ry(pitch) Rx(roll)
    pitch = math.asin(max(-1.0, min(1.0, -ned_from_body[2, 0])))
    if abs(math.cos(pitch)) > 1e-9:
        yaw = math.atan2(ned_from_body[1, 0], ned_from_body[0, 0])
        roll = math.atan2(ned_from_body[2, 1], ned_from_body[2, 2])
    else:
        roll = 0.0
        yaw = math.atan2(-ned_from_body[0, 1], ned_from_body[1, 1])
    yaw_deg = math.degrees(yaw) - convergence_deg
    yaw_deg = (yaw_deg + 180.0) % 360.0 - 180.0
    return yaw_deg, math.degrees(pitch), math.degrees(roll)


def grid_convergence_deg(crs: pyproj.CRS, lon_deg: float, lat_deg: float) -> float:
    """Grid azimuth of true north at (lon, lat), degrees clockwise from grid north.

    A DJI yaw (from true north) plus this value is the yaw from grid north.
    """
    to_grid = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    d = 1e-5
    x0, y0 = to_grid.transform(lon_deg, lat_deg)
    x1, y1 = to_grid.transform(lon_deg, lat_deg + d)
    return math.degrees(math.atan2(x1 - x0, y1 - y0))
