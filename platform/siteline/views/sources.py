"""Where view generation gets its geometry: an interface with an in-memory implementation (the tile
store provides another)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple, Protocol

import numpy as np
from scipy.spatial import cKDTree

from siteline.camera.pinhole import Camera


class ProbePoints(NamedTuple):
    """What a probe render of one view draws: ``xyz`` (N, 3) float32 site-local metres; ``spacing_m``
    (N,) float32 metres each point stands for (world splats; None: no level of detail, fixed
    splats only); ``kept`` (N,) bool, a class that is not ignored (None: all)."""

    xyz: np.ndarray
    spacing_m: np.ndarray | None = None
    kept: np.ndarray | None = None


class PointSource(Protocol):
    """Site-local geometry of one scene."""

    def points_for_view(self, camera: Camera, scale: float) -> ProbePoints:
        """The points a render of ``camera`` at ``scale`` needs."""

    def prefetch(self, cameras: Sequence[Camera], scale: float) -> None:
        """Say that probes of ``cameras`` at ``scale`` come next (a source may read them at once)."""

    def nearest_within(self, xyz: np.ndarray, radius_m: float) -> np.ndarray:
        """(M,) distance in metres from each query (M, 3) to the nearest point of the scene at full
        density (of both scenes of a pair where the source knows both), inf where none lies within
        ``radius_m``."""

    def count_above(self, xyz: np.ndarray, radius_m: float) -> np.ndarray:
        """(M,) number of points higher than each query within ``radius_m`` horizontally."""


def nearest_within(tree: cKDTree | None, xyz: np.ndarray, radius_m: float) -> np.ndarray:
    """(M,) distance in metres from each query (M, 3) to the nearest point of ``tree``, inf where
    none lies within ``radius_m`` (or the tree is None: no points)."""
    q = np.atleast_2d(np.asarray(xyz, dtype=np.float64))
    if tree is None:
        return np.full(len(q), np.inf)
    d, _ = tree.query(q, k=1, distance_upper_bound=radius_m)
    return np.asarray(d, dtype=np.float64)


class ArrayPointSource:
    """A whole (small) cloud held in memory: xyz (N, 3) float32 site-local metres, with each point's
    spacing in metres (world splats) and whether its class is kept, when known."""

    def __init__(
        self, xyz: np.ndarray, spacing_m: np.ndarray | None = None, kept: np.ndarray | None = None
    ) -> None:
        self.xyz = np.ascontiguousarray(xyz, dtype=np.float32)
        self.spacing_m = spacing_m
        self.kept = kept
        self._tree3 = cKDTree(self.xyz) if len(self.xyz) else None
        self._tree2 = cKDTree(self.xyz[:, :2]) if len(self.xyz) else None

    def points_for_view(self, camera: Camera, scale: float) -> ProbePoints:
        return ProbePoints(self.xyz, self.spacing_m, self.kept)

    def prefetch(self, cameras: Sequence[Camera], scale: float) -> None:
        return None

    def nearest_within(self, xyz: np.ndarray, radius_m: float) -> np.ndarray:
        return nearest_within(self._tree3, xyz, radius_m)

    def count_above(self, xyz: np.ndarray, radius_m: float) -> np.ndarray:
        q = np.atleast_2d(np.asarray(xyz, dtype=np.float64))
        if self._tree2 is None:
            return np.zeros(len(q), dtype=np.int64)
        out = np.zeros(len(q), dtype=np.int64)
        for i, idx in enumerate(self._tree2.query_ball_point(q[:, :2], r=radius_m)):
            if idx:
                out[i] = int((self.xyz[idx, 2] > q[i, 2]).sum())
        return out
