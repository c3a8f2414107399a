"""Poses with frame names (DESIGN.md §3): ``Rigid`` (rotation, translation) and ``Sim3`` (scale,
rotation, translation), each mapping points of frame ``src`` into frame ``dst``: x_dst = s R x_src + t.

Frames live in the names (``cam_from_world``, ``site_from_model``, ``prev_from_new``), and composing
two poses whose frames do not chain is refused: ``a_from_b @ b_from_c`` is ``a_from_c``;
``a_from_b @ c_from_d`` raises. Arrays are float64; translations in metres of ``dst``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from siteline.errors import GeometryError
from siteline.schema import JSON

ORTHONORMAL_TOL = 1e-6


def _rotation(R: Any) -> np.ndarray:
    R = np.asarray(R, dtype=np.float64).reshape(3, 3)
    if (
        not np.isfinite(R).all()
        or np.abs(R @ R.T - np.eye(3)).max() > ORTHONORMAL_TOL
        or np.linalg.det(R) < 0
    ):
        raise GeometryError("a pose rotation must be a finite proper rotation (orthonormal, det +1).")
    return R


def _vector(t: Any) -> np.ndarray:
    t = np.asarray(t, dtype=np.float64).reshape(3)
    if not np.isfinite(t).all():
        raise GeometryError("a pose translation must be finite.")
    return t


@dataclass(frozen=True, eq=False)
class Sim3:
    """x_dst = scale R x_src + t. R: (3, 3) float64 rotation; t: (3,) float64 metres; scale > 0."""

    dst: str
    src: str
    scale: float
    R: np.ndarray
    t: np.ndarray

    def __post_init__(self) -> None:
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise GeometryError(f"{self.name}: scale {self.scale} must be positive and finite.")
        object.__setattr__(self, "R", _rotation(self.R))
        object.__setattr__(self, "t", _vector(self.t))

    @property
    def name(self) -> str:
        return f"{self.dst}_from_{self.src}"

    def apply(self, xyz: np.ndarray) -> np.ndarray:
        """Points (N, 3) of ``src`` in ``dst`` (float64)."""
        return self.scale * np.asarray(xyz, dtype=np.float64) @ self.R.T + self.t

    def inverse(self) -> Sim3:
        Ri = self.R.T
        return type(self)._make(self.src, self.dst, 1.0 / self.scale, Ri, -(Ri @ self.t) / self.scale)

    def __matmul__(self, other: Sim3) -> Sim3:
        if self.src != other.dst:
            raise GeometryError(f"cannot compose {self.name} with {other.name}: {self.src} != {other.dst}.")
        return Sim3(self.dst, other.src, self.scale * other.scale, self.R @ other.R,
                    self.scale * (self.R @ other.t) + self.t)  # fmt: skip

    def matrix(self) -> np.ndarray:
        """(4, 4) float64 homogeneous form."""
        m = np.eye(4)
        m[:3, :3] = self.scale * self.R
        m[:3, 3] = self.t
        return m

    def to_dict(self) -> dict[str, JSON]:
        return {"frames": self.name, "scale": float(self.scale), "rotation": self.R.tolist(),
                "translation": self.t.tolist()}  # fmt: skip

    @classmethod
    def _make(cls, dst: str, src: str, scale: float, R: np.ndarray, t: np.ndarray) -> Sim3:
        return Sim3(dst, src, scale, R, t)


@dataclass(frozen=True, eq=False)
class Rigid(Sim3):
    """x_dst = R x_src + t (a Sim3 of scale 1)."""

    def __init__(self, dst: str, src: str, R: Any, t: Any) -> None:
        super().__init__(dst, src, 1.0, R, t)

    @classmethod
    def _make(cls, dst: str, src: str, scale: float, R: np.ndarray, t: np.ndarray) -> Rigid:
        return Rigid(dst, src, R, t)

    def __matmul__(self, other: Sim3) -> Sim3:
        out = Sim3.__matmul__(self, other)
        return Rigid(out.dst, out.src, out.R, out.t) if isinstance(other, Rigid) else out

    def to_dict(self) -> dict[str, JSON]:
        return {"frames": self.name, "rotation": self.R.tolist(), "translation": self.t.tolist()}
