"""A pair's changed regions as view planning sees them: a sample of each region's points, and how
many pixels of it a camera shows (with or without what the later scene draws in front of it)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from siteline.camera.pinhole import Camera

# the depth test of a probe works on cells of this many render pixels (the nearest point drawn in
# each): a probe reads points about 2 render pixels apart, so a cell holds tens of them
DEPTH_CELL_PX = 8
# a region's point is in front when it lies at most this far behind the nearest point of its cell
# (metres, plus DEPTH_SLACK of its depth): its own surface, drawn by the later scene, passes
DEPTH_SLACK_M = 0.5
DEPTH_SLACK = 0.02
# the probe's points the depth test draws, at most (every k-th of more)
DEPTH_SAMPLE = 200_000


@dataclass(frozen=True)
class ChangeSample:
    """The changed regions of a pair for view planning, regions numbered 0.. (the largest first).
    ``xyz`` (N, 3) float64 site-local metres: a sample of each region's changed points (both
    scenes'); ``region`` (N,) int64 the region of each; ``area_m2`` (N,) the surface each stands for
    (its region's surface shared among its sample); ``inside`` (R,) bool whether a region's centre
    lies inside the fence views are judged against."""

    xyz: np.ndarray
    region: np.ndarray
    area_m2: np.ndarray
    inside: np.ndarray

    @property
    def count(self) -> int:
        """The number of regions."""
        return len(self.inside)


def _pixel_area(sample: ChangeSample, cam: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each sample point's pixel (u, v as int64), depth (metres) and the pixels its surface covers
    through ``cam`` (0 outside the frame or behind it)."""
    uv, z = cam.project(sample.xyz)
    on = cam.in_frame(uv, z)
    f = max(cam.fx, cam.fy)
    with np.errstate(divide="ignore", invalid="ignore"):
        px = np.where(on, sample.area_m2 * (f / np.where(on, z, 1.0)) ** 2, 0.0)
    u = np.where(on, uv[:, 0], 0).astype(np.int64)
    v = np.where(on, uv[:, 1], 0).astype(np.int64)
    return u, v, z, px


def framed_pixels(sample: ChangeSample, cameras: Sequence[Camera], scale: float) -> np.ndarray:
    """(C, R) the pixels of each region inside each camera's frame at ``scale``, nothing in front
    considered: an upper bound of what a view can show."""
    out = np.zeros((len(cameras), sample.count))
    for i, camera in enumerate(cameras):
        _, _, _, px = _pixel_area(sample, camera.scaled(scale))
        out[i] = np.bincount(sample.region, weights=px, minlength=sample.count)
    return out


def shown_pixels(sample: ChangeSample, probe_xyz: np.ndarray, camera: Camera, scale: float) -> np.ndarray:
    """(R,) the pixels of each region a render of ``camera`` at ``scale`` shows: the region's points
    in the frame that lie in front of the nearest point the probe (``probe_xyz`` (M, 3) site-local
    metres, the later scene) draws in their cell of :data:`DEPTH_CELL_PX` pixels, within
    :data:`DEPTH_SLACK_M` + :data:`DEPTH_SLACK` of depth. A region gone from the later scene is
    judged against what now lies behind it, an added one against its own surface."""
    cam = camera.scaled(scale)
    gw, gh = -(-cam.width // DEPTH_CELL_PX), -(-cam.height // DEPTH_CELL_PX)
    nearest = np.full(gw * gh, np.inf)
    step = max(1, -(-len(probe_xyz) // DEPTH_SAMPLE))
    uv, z = cam.project(np.asarray(probe_xyz[::step], np.float64))
    on = cam.in_frame(uv, z)
    if on.any():
        cell = (uv[on, 1] // DEPTH_CELL_PX).astype(np.int64) * gw + (uv[on, 0] // DEPTH_CELL_PX).astype(
            np.int64
        )
        np.minimum.at(nearest, cell, z[on])
    u, v, zr, px = _pixel_area(sample, cam)
    front = zr <= nearest[(v // DEPTH_CELL_PX) * gw + u // DEPTH_CELL_PX] * (1 + DEPTH_SLACK) + DEPTH_SLACK_M
    return np.bincount(sample.region, weights=np.where(front, px, 0.0), minlength=sample.count)
