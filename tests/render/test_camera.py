"""Camera model: pycolmap conventions, scaling, frustum, JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from siteline.camera.pinhole import Camera
from siteline.errors import CameraError, SchemaError

from .helpers import oblique_camera


def test_convention_projection_matches_pycolmap() -> None:
    cam = oblique_camera(5645, 4082)
    pc, pose = cam.to_pycolmap()
    rng = np.random.default_rng(1)
    pts = rng.uniform(-20, 20, (1000, 3))
    uv, z = cam.project(pts)
    cam_pts = (pose.matrix()[:, :3] @ pts.T).T + pose.translation
    ref = pc.img_from_cam(cam_pts)
    front = z > 0
    assert np.abs(uv[front] - ref[front]).max() < 1e-4


def test_convention_pycolmap_quaternion_is_xyzw_and_round_trip_is_lossless() -> None:
    cam = oblique_camera()
    pc, pose = cam.to_pycolmap()
    q = pose.rotation.quat
    assert q.shape == (4,)
    back = Camera.from_pycolmap(pc, pose)
    assert np.abs(back.R - cam.R).max() < 1e-15
    assert back.t.tolist() == cam.t.tolist()
    assert (back.width, back.height, back.fx, back.fy, back.cx, back.cy) == (
        cam.width,
        cam.height,
        cam.fx,
        cam.fy,
        cam.cx,
        cam.cy,
    )
    ident = Camera.look_at((0, 0, 10), (0, 0, 0), 10, 10, 5.0)
    _, p = ident.to_pycolmap()
    # nadir camera: x right = east, y down = south, z forward = down; xyzw with w last
    assert np.allclose(np.abs(p.rotation.quat), [1, 0, 0, 0], atol=1e-12)


def test_center_and_forward() -> None:
    cam = Camera.look_at((1.0, 2.0, 30.0), (1.0, 2.0, 0.0), 100, 80, 50.0)
    assert np.allclose(cam.center, [1, 2, 30])
    assert np.allclose(cam.forward, [0, 0, -1])
    uv, z = cam.project(np.array([[1.0, 12.0, 0.0]]))
    assert z[0] == pytest.approx(30.0)
    assert uv[0, 1] < cam.cy  # north is image up for a nadir view


@pytest.mark.parametrize("s", [0.5, 0.25, 0.125, 0.3])
def test_scaled_matches_pycolmap_rescale(s: float) -> None:
    cam = oblique_camera(5645, 4082)
    pc, _ = cam.to_pycolmap()
    pc.rescale(s)
    mine = cam.scaled(s)
    assert (mine.width, mine.height) == (pc.width, pc.height)
    assert np.allclose([mine.fx, mine.fy, mine.cx, mine.cy], pc.params, rtol=0, atol=1e-12)


def test_frustum_planes_contain_exactly_the_visible_points() -> None:
    cam = oblique_camera()
    rng = np.random.default_rng(2)
    pts = rng.uniform(-60, 60, (20000, 3))
    uv, z = cam.project(pts)
    visible = (
        (z > 1e-3) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height)
    )
    planes = cam.frustum_planes(1e-3)
    inside = (pts @ planes[:, :3].T + planes[:, 3] >= -1e-9).all(axis=1)
    assert (inside == visible).mean() > 0.9999
    assert visible.sum() > 100


def test_json_round_trip_is_exact_and_schema_checked() -> None:
    cam = oblique_camera()
    again = Camera.from_dict(json.loads(json.dumps(cam.to_dict())))
    assert again == cam
    bad = cam.to_dict()
    bad["fx"] = -1
    with pytest.raises(SchemaError):
        Camera.from_dict(bad)


def test_bad_cameras_are_refused() -> None:
    with pytest.raises(CameraError, match="rotation"):
        Camera(10, 10, 5, 5, 5, 5, (1, 0, 0, 0, 1, 0, 0, 0, -1), (0, 0, 0))
    with pytest.raises(CameraError, match="finite"):
        Camera(10, 10, float("nan"), 5, 5, 5, (1, 0, 0, 0, 1, 0, 0, 0, 1), (0, 0, 0))
    with pytest.raises(CameraError):
        Camera(0, 10, 5, 5, 5, 5, (1, 0, 0, 0, 1, 0, 0, 0, 1), (0, 0, 0))
