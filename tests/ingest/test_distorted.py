"""Real DJI cameras are distorted: any COLMAP camera model is undistorted to COLMAP's own pinhole, the
XMP DewarpData path gives the same pinhole, and a mission with a distorted model goes to a release."""

from __future__ import annotations

import numpy as np
import pycolmap
import pytest
import sqlalchemy as sa
from sitehelpers import copy_mission, make_home

from siteline import pipeline
from siteline.camera.photos import PhotoMeta
from siteline.camera.pinhole import Camera, undistorted_pinhole
from siteline.catalog import open_catalog
from siteline.catalog.context import StageContext
from siteline.catalog.models import Scene, View
from siteline.catalog.scenes import scene_cameras
from siteline.records.params.pairs import PairParams
from siteline.register.xmp import camera_from_photo, dewarp_camera

DISTORTED = {
    "SIMPLE_RADIAL": [500.0, 330.0, 247.5, -0.03],
    "RADIAL": [500.0, 330.0, 247.5, -0.03, 0.01],
    "OPENCV": [500.0, 505.0, 331.2, 246.1, -0.04, 0.012, 0.0008, -0.0005],
    "FULL_OPENCV": [500.0, 505.0, 331.2, 246.1, -0.04, 0.012, 0.0008, -0.0005, 0.002, 0.0, 0.0, 0.0],
}


@pytest.mark.parametrize("model", sorted(DISTORTED))
def test_any_model_becomes_pycolmaps_undistorted_pinhole(model: str) -> None:
    cam = pycolmap.Camera(model=model, width=660, height=495, params=DISTORTED[model])
    ours = Camera.from_pycolmap(cam, pycolmap.Rigid3d())
    ref = pycolmap.undistort_camera(pycolmap.UndistortCameraOptions(), cam)
    assert ref.model_name == "PINHOLE" and (ours.width, ours.height) == (ref.width, ref.height)
    assert [ours.fx, ours.fy, ours.cx, ours.cy] == [float(v) for v in ref.params]
    assert (ours.width, ours.height) != (660, 495)  # undistortion changes the size


def test_xmp_dewarp_data_gives_the_same_pinhole_as_a_colmap_model() -> None:
    fx, fy, dcx, dcy, k1, k2, p1, p2, k3 = 500.0, 505.0, 1.2, -1.4, -0.04, 0.012, 0.0008, -0.0005, 0.002
    meta = PhotoMeta(
        file="DJI_0001.JPG", source="xmp", latitude_deg=45.4, longitude_deg=-75.7, absolute_altitude_m=120.0,
        gimbal_yaw_deg=10.0, gimbal_pitch_deg=-60.0, gimbal_roll_deg=0.0, calibrated_focal_length_px=fx,
        dewarp=(fx, fy, dcx, dcy, k1, k2, p1, p2, k3), width=660, height=495,
    )  # fmt: skip
    cam = camera_from_photo(meta, pyproj_utm18(), (445_000.0, 5_030_000.0, 0.0))
    colmap = pycolmap.Camera(
        model="FULL_OPENCV", width=660, height=495,
        params=[fx, fy, 330.0 + dcx, 247.5 + dcy, k1, k2, p1, p2, k3, 0.0, 0.0, 0.0],
    )  # fmt: skip
    ref = undistorted_pinhole(colmap)
    assert (cam.width, cam.height) == (ref.width, ref.height)
    assert [cam.fx, cam.fy, cam.cx, cam.cy] == [float(v) for v in ref.params]
    assert dewarp_camera(meta).model_name == "FULL_OPENCV"
    flat = PhotoMeta(**{**meta.__dict__, "dewarp": (fx, fy, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)})
    assert dewarp_camera(flat) is None  # no distortion: the calibrated pinhole as before


def pyproj_utm18():  # noqa: ANN201
    import pyproj

    return pyproj.CRS("EPSG:32618")


def _distort_model(mission) -> dict:  # noqa: ANN001
    """Rewrite the mission's COLMAP cameras as OPENCV with a little distortion; return one's params."""
    model_dir = mission / "colmap" / "sparse" / "0"
    rec = pycolmap.Reconstruction(str(model_dir))
    for cam in rec.cameras.values():
        fx, fy, cx, cy = (float(v) for v in cam.params)
        cam.model = pycolmap.CameraModelId.OPENCV
        cam.params = [fx, fy, cx, cy, -0.03, 0.008, 0.0004, -0.0003]
    rec.write(str(model_dir))
    return next(iter(rec.cameras.values()))


@pytest.mark.e2e
def test_a_mission_with_a_distorted_colmap_model_goes_to_a_release(tmp_path, synth_site) -> None:
    settings = make_home(tmp_path, site_dir=synth_site)
    missions = [copy_mission(synth_site, i, tmp_path / "missions") for i in (0, 1)]
    cams = [_distort_model(m) for m in missions]
    pinhole = undistorted_pinhole(cams[1])
    cat = open_catalog(settings)
    try:
        scenes = [
            pipeline.ingest(StageContext(cat, settings), m, "demo", workers=1).ingest.scene_id
            for m in missions
        ]
        with cat.transaction() as s:
            reg = s.get(Scene, scenes[1]).registration
            stored = scene_cameras(s, scenes[1])
        assert {m["model"] for m in reg["camera_models"].values()} == {"OPENCV"}
        assert reg["camera_models"][next(iter(reg["camera_models"]))]["undistorted"]["width"] == pinhole.width
        for _, cam in stored:
            assert (cam.width, cam.height) == (pinhole.width, pinhole.height)
            assert [cam.fx, cam.fy, cam.cx, cam.cy] == [float(v) for v in pinhole.params]
        one = {
            "vertical_fractions": [1.0],
            "forward_fractions": [0.0],
            "mirror": False,
        }  # one view per camera
        from siteline.records.params.release import ReleaseKnobs

        # the test is about the distorted model, not the views: their valid share on this small site
        # lies near the default min_valid 0.7
        params = PairParams(
            scale=0.5, point_size_px=3, views=4, seed=0, min_coverage=0.3, min_valid=0.6, view_params=one
        )
        info = pipeline.release(
            StageContext(cat, settings), "demo", "distorted", ReleaseKnobs.exactly(params)
        )
        assert info.items > 0
        with cat.transaction() as s:
            sizes = {(v.camera["width"], v.camera["height"]) for v in s.execute(sa.select(View)).scalars()}
        assert sizes == {
            (pinhole.width, pinhole.height)
        }  # views (and their renders) use the undistorted camera
    finally:
        cat.dispose()
    assert np.isfinite(info.items)
