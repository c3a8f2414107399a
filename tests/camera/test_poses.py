"""Pose types with frame names, and the conventions of dji.py pinned against a real DJI photo."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyproj
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from siteline.camera.dji import cam_from_world_rotation, gimbal_angles, grid_convergence_deg
from siteline.camera.photos import read_photo_meta
from siteline.camera.pinhole import Camera
from siteline.camera.poses import Rigid, Sim3
from siteline.errors import CameraError, GeometryError
from siteline.pointpass import dequantise, quantise

REAL_PHOTO = Path(__file__).resolve().parents[1] / "data" / "DJI_H20T.jpg"
UTM18N = pyproj.CRS("EPSG:32618")


def _rot(seed: int) -> np.ndarray:
    return Rotation.random(random_state=seed).as_matrix()


class TestRigidAndSim3:
    def test_compose_chains_frames_and_points(self) -> None:
        cam_from_world = Rigid("cam", "world", _rot(1), [1.0, 2.0, 3.0])
        world_from_model = Sim3("world", "model", 2.5, _rot(2), [10.0, -4.0, 0.5])
        cam_from_model = cam_from_world @ world_from_model
        assert cam_from_model.name == "cam_from_model" and type(cam_from_model) is Sim3
        x = np.random.default_rng(0).normal(size=(7, 3))
        assert np.allclose(cam_from_model.apply(x), cam_from_world.apply(world_from_model.apply(x)))
        assert type(cam_from_world @ Rigid("world", "site", _rot(3), [0, 0, 1])) is Rigid

    def test_refuses_frames_that_do_not_chain(self) -> None:
        a = Rigid("cam", "world", _rot(1), [0, 0, 0])
        with pytest.raises(GeometryError, match="cannot compose cam_from_world with cam_from_world"):
            a @ a

    def test_refuses_a_reflection_and_a_bad_scale(self) -> None:
        with pytest.raises(GeometryError):
            Rigid("a", "b", np.diag([1.0, 1.0, -1.0]), [0, 0, 0])
        with pytest.raises(GeometryError):
            Sim3("a", "b", 0.0, np.eye(3), [0, 0, 0])

    @settings(max_examples=60, deadline=None)
    @given(
        st.integers(0, 10_000),
        st.floats(0.01, 100.0),
        st.lists(st.floats(-1e4, 1e4), min_size=3, max_size=3),
    )
    def test_inverse_round_trip(self, seed: int, scale: float, t: list[float]) -> None:
        pose = Sim3("site", "model", scale, _rot(seed), t)
        x = np.random.default_rng(seed).normal(scale=50.0, size=(5, 3))
        back = pose.inverse().apply(pose.apply(x))
        assert pose.inverse().name == "model_from_site"
        assert np.allclose(back, x, atol=1e-9 * (1 + np.abs(t).max()) / min(scale, 1.0))

    def test_camera_pose_is_cam_from_world(self) -> None:
        cam = Camera.look_at((5.0, -20.0, 15.0), (0.0, 0.0, 0.0), 64, 48, 50.0)
        pose = cam.cam_from_world
        assert pose.name == "cam_from_world"
        assert np.allclose(pose.apply(cam.center[None])[0], 0.0, atol=1e-9)
        again = Camera.from_rigid(64, 48, 50.0, 50.0, 32.0, 24.0, pose)
        assert again == cam
        with pytest.raises(CameraError, match="cam_from_world"):
            Camera.from_rigid(64, 48, 50.0, 50.0, 32.0, 24.0, pose.inverse())


class TestDjiConventions:
    def test_convention_pitch_minus_90_is_nadir(self) -> None:
        R = cam_from_world_rotation(37.0, -90.0, 0.0)
        assert np.allclose(R[2], [0.0, 0.0, -1.0], atol=1e-12)  # the optical axis points down

    def test_convention_yaw_0_nadir_puts_the_image_top_north(self) -> None:
        R = cam_from_world_rotation(0.0, -90.0, 0.0)
        assert np.allclose(-R[1], [0.0, 1.0, 0.0], atol=1e-12)  # image up (-y) is grid north
        assert np.allclose(R[0], [1.0, 0.0, 0.0], atol=1e-12)  # image right is east

    def test_convention_grid_convergence_near_ottawa(self) -> None:
        # the meridian convergence (true north -> grid north) west of UTM 18N's central meridian is
        # -0.50 deg; grid_convergence_deg returns the grid azimuth of true north, its opposite
        gamma = -grid_convergence_deg(UTM18N, -75.7, 45.4)
        assert gamma == pytest.approx(-0.50, abs=0.01)
        R = cam_from_world_rotation(0.0, 0.0, 0.0, -gamma)  # a level camera, DJI yaw 0 (true north)
        assert math.degrees(math.atan2(R[2][0], R[2][1])) == pytest.approx(-gamma, abs=1e-9)

    def test_convention_real_dji_photo(self) -> None:
        meta = read_photo_meta(REAL_PHOTO)
        assert (meta.gimbal_yaw_deg, meta.gimbal_pitch_deg) == (32.5, -10.5)
        crs = pyproj.CRS("EPSG:32617")  # the photo is near Pittsburgh: UTM 17N
        conv = grid_convergence_deg(crs, meta.longitude_deg, meta.latitude_deg)
        R = cam_from_world_rotation(
            meta.gimbal_yaw_deg, meta.gimbal_pitch_deg, meta.gimbal_roll_deg or 0.0, conv
        )
        axis = R[2]  # the optical axis in the grid frame (x east, y north, z up)
        assert math.degrees(math.asin(axis[2])) == pytest.approx(-10.5, abs=1e-9)
        azimuth = math.degrees(math.atan2(axis[0], axis[1]))  # clockwise from grid north
        assert azimuth == pytest.approx(32.5 + conv, abs=1e-9)
        assert gimbal_angles(R, conv) == pytest.approx((32.5, -10.5, meta.gimbal_roll_deg or 0.0), abs=1e-9)

    @settings(max_examples=100, deadline=None)
    @given(st.floats(-180.0, 180.0), st.floats(-89.0, 89.0), st.floats(-45.0, 45.0), st.floats(-3.0, 3.0))
    def test_gimbal_angles_round_trip(self, yaw: float, pitch: float, roll: float, conv: float) -> None:
        R = cam_from_world_rotation(yaw, pitch, roll, conv)
        y, p, r = gimbal_angles(R, conv)
        assert np.allclose(cam_from_world_rotation(y, p, r, conv), R, atol=1e-9)
        assert p == pytest.approx(pitch, abs=1e-7) and r == pytest.approx(roll, abs=1e-7)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.floats(-5_000.0, 5_000.0), min_size=3, max_size=3),
    st.sampled_from([1e-4, 1e-3, 1e-2]),
)
def test_quantisation_round_trip_is_within_half_a_quantum(xyz: list[float], quantum: float) -> None:
    local = np.array([xyz])
    origin = np.floor(local[0] / 100.0) * 100.0
    back = dequantise(quantise(local, origin, quantum), origin, quantum)
    assert np.abs(back - local).max() <= quantum / 2 + 1e-9
