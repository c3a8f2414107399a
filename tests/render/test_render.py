"""The z-buffer renderer: conventions, occlusion, determinism, invalid points, scale, extremes."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from siteline.camera.pinhole import Camera
from siteline.errors import RenderError
from siteline.records.params.render import RenderParams
from siteline.render.georef import render_georeferenced
from siteline.render.zbuffer import render_points

from .helpers import box_scene, oblique_camera, plane_points

S1 = RenderParams(scale=1.0)
S1_64 = RenderParams(scale=1.0, precision="float64")


def test_pixels_follow_pycolmap_projection() -> None:
    cam = oblique_camera(706, 510)
    pc, pose = cam.to_pycolmap()
    rng = np.random.default_rng(3)
    pts = rng.uniform(-15, 15, (400, 3))
    cam_pts = pts @ pose.matrix()[:, :3].T + pose.translation
    uv = pc.img_from_cam(cam_pts)
    frac = uv - np.floor(uv)
    ok = (cam_pts[:, 2] > 0) & (frac > 1e-3).all(1) & (frac < 1 - 1e-3).all(1)
    ok &= (uv[:, 0] >= 0) & (uv[:, 0] < 706) & (uv[:, 1] >= 0) & (uv[:, 1] < 510)
    pts, uv = pts[ok], uv[ok]
    for prec in ("float32", "float64"):
        r = render_points(pts.astype(np.float32), cam, RenderParams(scale=1.0, precision=prec))
        expect_px = np.floor(uv).astype(int)
        # every winner sits in the pixel pycolmap projects it to
        rows, cols = np.nonzero(r.hit)
        w = r.index[rows, cols]
        assert (expect_px[w, 0] == cols).all() and (expect_px[w, 1] == rows).all()
        # and every pixel pycolmap says is reached is hit
        assert r.hit[expect_px[:, 1], expect_px[:, 0]].all()


def test_plane_at_known_depth() -> None:
    cam = Camera.look_at((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), 64, 48, fx=40.0)
    pts = plane_points(0.0, 12.0, 0.05).astype(np.float32)
    r = render_points(pts, cam, S1)
    assert r.coverage == 1.0
    assert np.abs(r.depth - 10.0).max() < 1e-5


def test_near_square_occludes_far_square() -> None:
    cam = Camera.look_at((0.0, 0.0, 20.0), (0.0, 0.0, 0.0), 50, 50, fx=50.0)
    far = plane_points(0.0, 10.0, 0.05)
    near = plane_points(5.0, 2.0, 0.02)
    pts = np.concatenate([far, near]).astype(np.float32)
    label = np.r_[np.zeros(len(far), np.uint8), np.ones(len(near), np.uint8)]
    r = render_points(pts, cam, S1, {"label": label})
    centre = r.attributes["label"][20:30, 20:30]
    assert (centre == 1).all()
    assert np.allclose(r.depth[20:30, 20:30], 15.0, atol=1e-4)
    assert (r.attributes["label"][:5, :5] == 0).all()


def test_duplicates_are_deterministic_and_smallest_index_wins() -> None:
    cam = oblique_camera()
    xyz, rgb, _ = box_scene(1, 4000)
    pts = np.concatenate([xyz, xyz, xyz]).astype(np.float32)
    rgb3 = np.concatenate([rgb, rgb // 2, rgb // 3])
    a = render_points(pts, cam, S1, {"rgb": rgb3})
    b = render_points(pts, cam, RenderParams(scale=1.0, chunk_points=777), {"rgb": rgb3})
    assert np.array_equal(a.index, b.index) and np.array_equal(a.attributes["rgb"], b.attributes["rgb"])
    assert (a.index[a.hit] < len(xyz)).all()


def test_empty_input_gives_all_miss() -> None:
    r = render_points(np.zeros((0, 3), np.float32), oblique_camera(), S1, {"rgb": np.zeros((0, 3), np.uint8)})
    assert not r.hit.any() and r.coverage == 0.0
    assert np.isnan(r.depth).all() and (r.index == -1).all()
    assert r.rgb.shape == (120, 160, 3)


def test_invalid_points_never_appear() -> None:
    cam = Camera.look_at((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), 32, 32, fx=16.0)
    bad = np.array(
        [
            [0.0, 0.0, 10.0],  # at the camera centre: z = 0
            [0.0, 0.0, 20.0],  # behind the camera
            [np.nan, 0.0, 0.0],
            [0.0, np.inf, 0.0],
            [-np.inf, 0.0, 0.0],
            [1e30, 0.0, 0.0],
            [0.0, 0.0, 10.0 - 1e-4],  # in front, but nearer than the near plane
        ],
        dtype=np.float32,
    )
    good = np.array([[0.1, 0.1, 0.0]], dtype=np.float32)
    r = render_points(np.concatenate([bad, good]), cam, S1)
    assert r.hit.sum() == 1
    assert set(np.unique(r.index[r.hit])) == {len(bad)}
    assert r.stats["points_in_frustum"] == 1


def test_point_size_three_covers_a_disk_and_nearer_wins() -> None:
    cam = Camera.look_at((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), 21, 21, fx=10.0)
    far = np.array([[0.0, 0.0, 0.0]], np.float32)
    near = np.array([[0.5, 0.0, 1.0]], np.float32)  # neighbouring pixel, nearer
    r = render_points(np.concatenate([far, near]), cam, RenderParams(scale=1.0, point_size_px=3))
    assert r.hit.sum() == 12  # two 3x3 splats overlapping in 6 pixels
    overlap = r.hit & (r.index == 1)
    assert overlap.sum() == 9


def test_scale_equals_pycolmap_rescaled_camera() -> None:
    cam = oblique_camera(1280, 960)
    xyz, rgb, _ = box_scene(2, 20000)
    pc, pose = cam.to_pycolmap()
    for s in (0.5, 0.25, 0.125):
        pcs = type(pc)(pc.todict())
        pcs.rescale(s)
        ref_cam = Camera.from_pycolmap(pcs, pose)
        a = render_points(xyz.astype(np.float32), cam, RenderParams(scale=s), {"rgb": rgb})
        b = render_points(xyz.astype(np.float32), ref_cam, S1, {"rgb": rgb})
        assert np.array_equal(a.index, b.index)
        assert np.array_equal(a.rgb, b.rgb)


ORIGIN = (445000.0, 5030000.0, 80.0)


def test_georeferenced_render_equals_render_at_origin() -> None:
    xyz, rgb, _ = box_scene(4, 30000)
    cam = oblique_camera(706, 510)
    at_origin = render_points(xyz.astype(np.float32), cam, S1, {"rgb": rgb})
    geo = xyz + np.asarray(ORIGIN)
    shifted = render_georeferenced(geo, ORIGIN, cam, S1, {"rgb": rgb})
    assert np.array_equal(at_origin.index, shifted.index)
    assert np.array_equal(at_origin.depth, shifted.depth, equal_nan=True)
    assert np.array_equal(at_origin.rgb, shifted.rgb)
    assert at_origin.hit.sum() > 5000


def test_naive_float32_world_render_differs() -> None:
    """What the site-local path prevents: float32 world coordinates near 5e6 m are 0.5 m apart."""
    xyz, rgb, _ = box_scene(4, 30000)
    cam = oblique_camera(706, 510)
    at_origin = render_points(xyz.astype(np.float32), cam, S1)
    geo = (xyz + np.asarray(ORIGIN)).astype(np.float32)
    world_cam = cam.with_pose(cam.R, cam.t - cam.R @ np.asarray(ORIGIN))
    # a renderer that skipped the site-local shift and projected float32 world coordinates
    c = torch.from_numpy(geo) @ torch.from_numpy(world_cam.R.T.astype(np.float32)) + torch.from_numpy(
        world_cam.t.astype(np.float32)
    )
    u = (c[:, 0] / c[:, 2] * cam.fx + cam.cx).floor().numpy()
    v = (c[:, 1] / c[:, 2] * cam.fy + cam.cy).floor().numpy()
    uv0, _ = cam.project(xyz)
    moved = (u != np.floor(uv0[:, 0])) | (v != np.floor(uv0[:, 1]))
    assert moved.mean() > 0.2
    inside = (u >= 0) & (u < 706) & (v >= 0) & (v < 510) & (c[:, 2].numpy() > 0)
    naive_hit = np.zeros_like(at_origin.hit)
    naive_hit[v[inside].astype(int), u[inside].astype(int)] = True
    assert (naive_hit != at_origin.hit).sum() > 1000


def test_georeferenced_input_must_be_float64() -> None:
    with pytest.raises(Exception, match="float64"):
        render_georeferenced(np.zeros((3, 3), np.float32), ORIGIN, oblique_camera())


def test_float64_points_are_refused_by_site_local_renderer() -> None:
    with pytest.raises(RenderError, match="float32"):
        render_points(np.zeros((3, 3)), oblique_camera())


def test_camera_one_centimetre_from_surface() -> None:
    cam = Camera.look_at((0.0, 0.0, 0.01), (0.0, 0.0, 0.0), 64, 64, fx=32.0)
    pts = plane_points(0.0, 0.012, 0.0002).astype(np.float32)
    r = render_points(pts, cam, S1)
    assert r.coverage > 0.9
    assert np.nanmax(np.abs(r.depth - 0.01)) < 1e-6
    assert not np.isnan(r.depth[r.hit]).any()


def test_grazing_view_89_9_degrees() -> None:
    pts = plane_points(0.0, 50.0, 0.05).astype(np.float32)
    ang = np.deg2rad(89.9)
    target = np.array([0.0, 40.0, 0.0])
    center = target - 40.0 * np.array([0.0, np.sin(ang), -np.cos(ang)])
    cam = Camera.look_at(center, target, 128, 96, fx=100.0)
    r = render_points(pts, cam, S1)
    assert r.hit.any()
    d = r.depth[r.hit]
    assert np.isfinite(d).all() and (d > 0).all()
    assert not r.hit[:40].any()  # the upper image sees the sky above the horizon


def test_one_point() -> None:
    cam = Camera.look_at((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), 11, 11, fx=10.0)
    r = render_points(np.array([[0.0, 0.0, 0.0]], np.float32), cam, S1, {"c": np.array([7], np.uint8)})
    assert r.hit.sum() == 1 and r.hit[5, 5] and r.attributes["c"][5, 5] == 7 and r.depth[5, 5] == 10.0


def _random_rotation(a: float, b: float, c: float) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("zyx", [a, b, c]).as_matrix()


@settings(max_examples=25, deadline=None)
@given(
    cells=st.lists(
        st.tuples(st.integers(0, 39), st.integers(0, 29), st.floats(0.1, 0.9), st.floats(0.1, 0.9)),
        min_size=1,
        max_size=60,
    ),
    depth_ids=st.data(),
    angles=st.tuples(st.floats(-3.1, 3.1), st.floats(-1.5, 1.5), st.floats(-3.1, 3.1)),
    shift=st.tuples(st.floats(-500, 500), st.floats(-500, 500), st.floats(-50, 50)),
)
def test_rigid_motion_of_scene_and_camera_changes_nothing(cells, depth_ids, angles, shift) -> None:
    cam = Camera.look_at((3.0, -2.0, 12.0), (0.0, 0.0, 0.0), 40, 30, fx=30.0)
    depths = depth_ids.draw(
        st.lists(st.integers(0, 400), min_size=len(cells), max_size=len(cells), unique=True)
    )
    # points built from pixel positions away from pixel edges and distinct depths
    uvz = np.array(
        [(i + fu, j + fv, 2.0 + 0.05 * d) for (i, j, fu, fv), d in zip(cells, depths, strict=True)]
    )
    rays = np.stack([(uvz[:, 0] - cam.cx) / cam.fx, (uvz[:, 1] - cam.cy) / cam.fy, np.ones(len(uvz))], 1)
    pts = (rays * uvz[:, 2:3] - cam.t) @ cam.R
    M = _random_rotation(*angles)
    T = np.asarray(shift)
    moved_pts = pts @ M.T + T
    moved_cam = cam.with_pose(cam.R @ M.T, cam.t - cam.R @ M.T @ T)
    attrs = {"id": np.arange(len(pts), dtype=np.int32)}
    a = render_points(pts.astype(np.float32), cam, S1_64, attrs)
    b = render_points(moved_pts.astype(np.float32), moved_cam, S1_64, attrs)
    assert np.array_equal(a.hit, b.hit)
    assert np.array_equal(a.index, b.index)
    assert np.array_equal(a.attributes["id"], b.attributes["id"])
    assert np.allclose(a.depth, b.depth, rtol=1e-4, equal_nan=True)
