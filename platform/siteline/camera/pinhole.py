"""Pinhole cameras in the COLMAP/OpenCV convention (DESIGN.md §3).

Camera axes: x right, y down, z forward. ``cam_from_world`` (R, t): x_cam = R x_world + t, where the
world is the site-local frame (metres). Camera centre C = -R^T t. Pixel centres sit at (i + 0.5,
j + 0.5): a point projecting to u in [i, i + 1) lands in column i. This module is the one place that
converts to and from pycolmap.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, NotRequired, TypedDict

import numpy as np
import numpy.typing as npt

from siteline.camera.intrinsics import Intrinsics
from siteline.camera.poses import Rigid
from siteline.errors import CameraError
from siteline.schema import JSON, json_int, json_numbers, json_object, json_or_none, validated
from siteline.tolerances import snap

if TYPE_CHECKING:
    import pycolmap

ORTHONORMAL_TOL = 1e-6


def _round_half_up(x: float) -> int:
    # COLMAP's Camera::Rescale uses std::round (half away from zero); Python's round() is banker's.
    return int(math.floor(x + 0.5))


class PoseDoc(TypedDict):
    """A camera's pose: ``rotation`` (3 x 3, rows) and ``translation`` (3) of cam_from_world."""

    rotation: list[list[float]]
    translation: list[float]


class CameraDoc(TypedDict):
    """A camera as ``schema/camera.schema.json`` states it: model, image size (pixels), intrinsics
    (pixels) and pose (site-local frame, metres)."""

    model: NotRequired[str]
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    cam_from_world: PoseDoc


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: size (pixels), intrinsics (pixels), pose ``cam_from_world`` (float64).

    rotation: R row-major as 9 floats; translation: t as 3 floats (metres).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    rotation: tuple[float, ...]
    translation: tuple[float, float, float]

    def __post_init__(self) -> None:
        if not (isinstance(self.width, int | np.integer) and isinstance(self.height, int | np.integer)):
            raise CameraError(f"camera size must be integers, got {self.width!r} x {self.height!r}.")
        if self.width <= 0 or self.height <= 0 or self.width > 100_000 or self.height > 100_000:
            raise CameraError(f"camera size {self.width} x {self.height} px is not usable.")
        intr = (self.fx, self.fy, self.cx, self.cy)
        if not all(math.isfinite(v) for v in intr):
            raise CameraError(f"camera intrinsics {intr} are not finite.")
        if self.fx <= 0 or self.fy <= 0:
            raise CameraError(f"camera focal lengths must be positive, got fx={self.fx}, fy={self.fy}.")
        if len(self.rotation) != 9 or len(self.translation) != 3:
            raise CameraError("camera pose needs a 3x3 rotation and a 3-vector translation.")
        R = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        t = np.asarray(self.translation, dtype=np.float64)
        if not (np.isfinite(R).all() and np.isfinite(t).all()):
            raise CameraError("camera pose has non-finite values.")
        if np.abs(R @ R.T - np.eye(3)).max() > ORTHONORMAL_TOL or np.linalg.det(R) < 0:
            raise CameraError("camera rotation is not a proper rotation (orthonormal, det +1).")

    @property
    def intrinsics(self) -> Intrinsics:
        """Size and intrinsics (pixels) without the pose."""
        return Intrinsics(self.width, self.height, self.fx, self.fy, self.cx, self.cy)

    # -- construction ------------------------------------------------------------------------
    @classmethod
    def from_pose(
        cls,
        width: int,
        height: int,
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        R: npt.ArrayLike,
        t: npt.ArrayLike,
    ) -> Camera:
        """From intrinsics and ``cam_from_world`` R (3, 3), t (3,) float64."""
        R = np.asarray(R, dtype=np.float64).reshape(3, 3)
        t = np.asarray(t, dtype=np.float64).reshape(3)
        return cls(
            int(width),
            int(height),
            float(fx),
            float(fy),
            float(cx),
            float(cy),
            tuple(float(v) for v in R.ravel()),
            (float(t[0]), float(t[1]), float(t[2])),
        )

    @classmethod
    def look_at(
        cls,
        center: npt.ArrayLike,
        target: npt.ArrayLike,
        width: int,
        height: int,
        fx: float,
        fy: float | None = None,
        cx: float | None = None,
        cy: float | None = None,
    ) -> Camera:
        """A camera at ``center`` (site-local metres) looking at ``target``; image up follows the
        site's up (+z). Looking straight down (nadir), image up points to +y (north).
        """
        C = np.asarray(center, dtype=np.float64)
        z = np.asarray(target, dtype=np.float64) - C
        if not np.isfinite(z).all() or np.linalg.norm(z) == 0:
            raise CameraError("look_at needs a target distinct from the centre.")
        z /= np.linalg.norm(z)
        upv = np.array([0.0, 0.0, 1.0])
        if np.linalg.norm(np.cross(z, upv)) < 1e-9:
            upv = np.array([0.0, 1.0, 0.0]) if abs(z[2]) > 0.5 else np.array([0.0, 0.0, 1.0])
        x = np.cross(z, upv)  # right = forward x up ... then y (down) = forward x right
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        R = np.stack([x, y, z])  # rows: camera axes in world
        return cls.from_pose(
            width,
            height,
            fx,
            fy if fy is not None else fx,
            cx if cx is not None else width / 2.0,
            cy if cy is not None else height / 2.0,
            R,
            -R @ C,
        )

    # -- geometry ----------------------------------------------------------------------------
    @property
    def R(self) -> np.ndarray:
        """cam_from_world rotation (3, 3) float64."""
        return np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)

    @property
    def t(self) -> np.ndarray:
        """cam_from_world translation (3,) float64, metres."""
        return np.asarray(self.translation, dtype=np.float64)

    @property
    def cam_from_world(self) -> Rigid:
        """The pose: world (site-local metres) -> camera axes (x right, y down, z forward)."""
        return Rigid("cam", "world", self.R, self.t)

    @classmethod
    def from_rigid(
        cls, width: int, height: int, fx: float, fy: float, cx: float, cy: float, cam_from_world: Rigid
    ) -> Camera:
        """From intrinsics (pixels) and a ``cam_from_world`` :class:`siteline.camera.poses.Rigid`."""
        if cam_from_world.name != "cam_from_world":
            raise CameraError(f"a camera pose must be cam_from_world, got {cam_from_world.name}.")
        return cls.from_pose(width, height, fx, fy, cx, cy, cam_from_world.R, cam_from_world.t)

    @property
    def center(self) -> np.ndarray:
        """Camera centre in the world (site-local) frame, (3,) float64 metres."""
        return -self.R.T @ self.t

    @property
    def forward(self) -> np.ndarray:
        """Optical axis (camera +z) in the world frame, unit (3,)."""
        return self.R[2].copy()

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def with_pose(self, R: np.ndarray, t: np.ndarray) -> Camera:
        return Camera.from_pose(self.width, self.height, self.fx, self.fy, self.cx, self.cy, R, t)

    def with_center(self, center: npt.ArrayLike) -> Camera:
        """Same orientation and intrinsics, centre moved to ``center`` (site-local metres)."""
        R = self.R
        return self.with_pose(R, -R @ np.asarray(center, dtype=np.float64))

    def snapped(self, center_quantum_m: float, rotation_quantum: float) -> Camera:
        """The same camera with its centre rounded to ``center_quantum_m`` (site-local metres) and its
        rotation to a unit quaternion (w >= 0) whose components are rounded to ``rotation_quantum``:
        poses that differ only by registration noise below the quanta become bit-identical."""
        from scipy.spatial.transform import Rotation

        q = Rotation.from_matrix(self.R).as_quat()  # x, y, z, w
        if q[3] < 0:
            q = -q
        R = Rotation.from_quat(snap(q, rotation_quantum)).as_matrix()
        C = snap(self.center, center_quantum_m)
        return self.with_pose(R, -R @ C)

    def scaled(self, s: float) -> Camera:
        """The camera rendering at scale ``s`` (as pycolmap ``Camera.rescale(s)``).

        The size is rounded (half up); fx, cx scale by new_width / width and fy, cy by
        new_height / height, so the image frame and its content stay aligned.
        """
        if not (isinstance(s, int | float) and math.isfinite(s) and s > 0):
            raise CameraError(f"render scale must be a positive number, got {s!r}.")
        if s == 1:
            return self
        w = max(1, _round_half_up(self.width * s))
        h = max(1, _round_half_up(self.height * s))
        sx, sy = w / self.width, h / self.height
        return replace(
            self, width=w, height=h, fx=self.fx * sx, fy=self.fy * sy, cx=self.cx * sx, cy=self.cy * sy
        )

    def project(self, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) float64 and depth z_cam (N,) of world points (N, 3), float64."""
        cam = np.asarray(xyz, dtype=np.float64) @ self.R.T + self.t
        z = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.stack([self.fx * cam[:, 0] / z + self.cx, self.fy * cam[:, 1] / z + self.cy], axis=1)
        return uv, z

    def in_frame(self, uv: np.ndarray, z: np.ndarray) -> np.ndarray:
        """(N,) bool: which of :meth:`project`'s points lie in front of the camera and in its image."""
        return (
            (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < self.width) & (uv[:, 1] >= 0) & (uv[:, 1] < self.height)
        )

    def frustum_planes(self, near_m: float = 1e-3, far_m: float | None = None) -> np.ndarray:
        """Inward planes (K, 4) float64 [n, d] with n . x + d >= 0 inside (site-local metres).

        Order: near, left, right, top, bottom[, far]. The side planes pass through the image edges
        (u = 0, u = width, v = 0, v = height).
        """
        R, C = self.R, self.center
        corners_px = [(0.0, 0.0), (self.width, 0.0), (self.width, self.height), (0.0, self.height)]
        rays = []
        for u, v in corners_px:
            d_cam = np.array([(u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0])
            rays.append(R.T @ d_cam)
        f = self.forward
        planes = [np.append(f, -f @ C - near_m)]
        # left: corners 0 (top-left) and 3 (bottom-left); inward normal points to +x of the camera
        for a, b in ((3, 0), (1, 2), (0, 1), (2, 3)):
            n = np.cross(rays[a], rays[b])
            n /= np.linalg.norm(n)
            planes.append(np.append(n, -n @ C))
        if far_m is not None:
            planes.append(np.append(-f, f @ C + far_m))
        return np.array(planes)

    # -- conversions ---------------------------------------------------------------------------
    def to_pycolmap(self) -> tuple[pycolmap.Camera, pycolmap.Rigid3d]:
        """(pycolmap.Camera PINHOLE, pycolmap.Rigid3d cam_from_world)."""
        import pycolmap

        cam = pycolmap.Camera(
            model="PINHOLE", width=self.width, height=self.height, params=[self.fx, self.fy, self.cx, self.cy]
        )
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(self.R), self.t)
        return cam, pose

    @classmethod
    def from_pycolmap(cls, camera: pycolmap.Camera, cam_from_world: pycolmap.Rigid3d) -> Camera:
        """From a pycolmap camera and a Rigid3d ``cam_from_world``. PINHOLE and SIMPLE_PINHOLE are taken
        as they are; any other model pycolmap knows (OPENCV, SIMPLE_RADIAL, FULL_OPENCV, ...) becomes
        its undistorted pinhole camera (:func:`undistorted_pinhole`, DESIGN.md §3), the camera COLMAP's
        image undistorter writes: renders are distortion-free."""
        pinhole = undistorted_pinhole(camera)
        fx, fy, cx, cy = (float(v) for v in pinhole.params)
        return cls.from_pose(
            pinhole.width,
            pinhole.height,
            fx,
            fy,
            cx,
            cy,
            cam_from_world.rotation.matrix(),
            cam_from_world.translation,
        )

    def to_dict(self) -> dict[str, JSON]:
        """JSON form (``schema/camera.schema.json``); floats round-trip exactly."""
        return {
            "model": "PINHOLE",
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "cam_from_world": {
                "rotation": [list(self.rotation[0:3]), list(self.rotation[3:6]), list(self.rotation[6:9])],
                "translation": list(self.translation),
            },
        }

    @classmethod
    def from_dict(cls, raw: object, source: str = "camera") -> Camera:
        doc = validated(raw, "camera.schema.json", source, CameraDoc)
        pose = doc["cam_from_world"]
        try:
            return cls.from_pose(
                doc["width"],
                doc["height"],
                doc["fx"],
                doc["fy"],
                doc["cx"],
                doc["cy"],
                np.asarray(pose["rotation"], dtype=np.float64),
                np.asarray(pose["translation"]),
            )
        except CameraError as exc:
            raise CameraError(f"{source}: {exc}") from exc


def model_name(camera: pycolmap.Camera) -> str:
    """The COLMAP model name of a pycolmap camera (``OPENCV``, ``PINHOLE``, ...)."""
    name = camera.model_name if hasattr(camera, "model_name") else str(camera.model)
    return name.split(".")[-1]


def undistorted_pinhole(camera: pycolmap.Camera) -> pycolmap.Camera:
    """The PINHOLE pycolmap camera of a pycolmap camera of any model: itself when it has no
    distortion (PINHOLE, SIMPLE_PINHOLE as PINHOLE), else ``pycolmap.undistort_camera`` with COLMAP's
    default options (the size and principal point change: 5280 x 3956 raw -> ~5645 x 4082)."""
    import pycolmap

    name = model_name(camera)
    p = [float(v) for v in camera.params]
    if name == "PINHOLE":
        return camera
    if name == "SIMPLE_PINHOLE":
        return pycolmap.Camera(
            model="PINHOLE", width=camera.width, height=camera.height, params=[p[0], p[0], p[1], p[2]]
        )
    try:
        out = pycolmap.undistort_camera(pycolmap.UndistortCameraOptions(), camera)
    except Exception as exc:  # pycolmap raises plain RuntimeErrors on unusable parameters
        raise CameraError(f"camera model {name} with parameters {p} cannot be undistorted: {exc}") from exc
    if model_name(out) != "PINHOLE":
        raise CameraError(f"undistorting a {name} camera gave a {model_name(out)} camera, not PINHOLE.")
    return out


@dataclass(frozen=True)
class CameraModel:
    """A COLMAP camera model as the catalog records it: pycolmap's model name, the image size (pixels)
    and the model's parameters in pycolmap's order; ``undistorted``: the pinhole renders use in its
    place (None for a pinhole itself)."""

    model: str
    width: int
    height: int
    params: tuple[float, ...]
    undistorted: CameraModel | None = None

    def to_dict(self) -> dict[str, JSON]:
        doc: dict[str, JSON] = {
            "model": self.model,
            "width": self.width,
            "height": self.height,
            "params": list(self.params),
        }
        if self.undistorted is not None:
            doc["undistorted"] = self.undistorted.to_dict()
        return doc

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> CameraModel:
        inner = json_or_none(json_object, doc.get("undistorted"), "undistorted")
        return cls(
            str(doc["model"]), json_int(doc["width"], "width"), json_int(doc["height"], "height"),
            tuple(float(v) for v in json_numbers(doc["params"], "params")), cls.from_dict(inner) if inner else None,
        )  # fmt: skip


def distortion_model(camera: pycolmap.Camera) -> CameraModel | None:
    """What the catalog records of a distorted camera: its model, size and parameters, and the
    undistorted pinhole renders use; None for a pinhole camera."""
    name = model_name(camera)
    if name in ("PINHOLE", "SIMPLE_PINHOLE"):
        return None
    pinhole = undistorted_pinhole(camera)
    return CameraModel(
        name, int(camera.width), int(camera.height), tuple(float(v) for v in camera.params),
        CameraModel("PINHOLE", int(pinhole.width), int(pinhole.height), tuple(float(v) for v in pinhole.params)),
    )  # fmt: skip
