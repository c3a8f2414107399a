"""The edge trim: a world splat that reaches past its surface's edge gives those pixels back to the
farther surface behind, and nothing changes inside a surface or where nothing lies behind it."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from siteline.camera.pinhole import Camera
from siteline.records.params.render import RenderParams
from siteline.render.zbuffer import render_points

from .helpers import plane_points

WORLD = RenderParams(scale=1.0, splat="world")
TRIM = RenderParams(scale=1.0, splat="world", trim_edges=True)


def _plate_over_ground(seed: int = 1, height_m: float = 10.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A square plate 8 m across at ``height_m`` (0.4 m jittered samples) over dense ground at 0 m:
    points, spacings, labels (1 plate, 0 ground)."""
    rng = np.random.default_rng(seed)
    ground = plane_points(0.0, 20.0, 0.05)
    plate = plane_points(height_m, 3.8, 0.4)
    plate[:, :2] += rng.uniform(-0.2, 0.2, (len(plate), 2))
    pts = np.concatenate([ground, plate]).astype(np.float32)
    spacing = np.r_[np.full(len(ground), 0.05), np.full(len(plate), 0.4)].astype(np.float32)
    label = np.r_[np.zeros(len(ground), np.uint8), np.ones(len(plate), np.uint8)]
    return pts, spacing, label


def _camera() -> Camera:
    # nadir from 30 m: the plate (+-4 m at 20 m depth) spans +-24 px about the image centre
    return Camera.look_at((0.0, 0.0, 30.0), (0.0, 0.0, 0.0), 120, 120, fx=120.0)


def _true_plate(cam: Camera) -> np.ndarray:
    """Pixels whose centre's ray meets the plate (|x|, |y| <= 4 m at z = 10 m), exactly."""
    u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    x = (u - cam.cx) / cam.fx * 20.0
    y = (v - cam.cy) / cam.fy * 20.0
    return (np.abs(x) <= 4.0) & (np.abs(y) <= 4.0)


def test_a_plate_drawn_with_trimmed_edges_ends_where_its_surface_ends() -> None:
    pts, spacing, label = _plate_over_ground()
    cam = _camera()
    truth = _true_plate(cam)
    plain = render_points(pts, cam, WORLD, {"label": label}, spacing_m=spacing)
    trimmed = render_points(pts, cam, TRIM, {"label": label}, spacing_m=spacing)
    over_plain = (plain.attributes["label"] == 1) & ~truth
    over_trim = (trimmed.attributes["label"] == 1) & ~truth
    under_trim = (trimmed.attributes["label"] == 0) & truth
    perimeter = 4 * 48
    assert over_plain.sum() > perimeter  # the splats reach more than a pixel past every edge
    assert over_trim.sum() < 0.1 * over_plain.sum()
    # the edge is drawn within two pixels of the true one: what the trim takes from the plate is its
    # outermost two pixels at most, about one on average (the last samples leave the edge anywhere
    # within a spacing beyond them: 2.4 px here)
    depth_in = ndimage.distance_transform_cdt(truth, metric="chessboard")
    assert under_trim.sum() <= 1.2 * perimeter and (depth_in[under_trim] <= 2).all()
    assert trimmed.stats["trimmed"] > 0
    # the trimmed pixels show the ground behind, drawn and labelled as ground
    gone = (plain.attributes["label"] == 1) & (trimmed.attributes["label"] == 0)
    assert gone.any() and trimmed.hit[gone].all()
    assert np.allclose(trimmed.depth[gone], 30.0, atol=0.01)


def test_a_plate_a_tenth_of_its_depth_above_the_ground_is_trimmed_too() -> None:
    # 2.5 m over the ground seen from 27.5 m: the ground lies within a tenth of the depth behind the
    # plate (what the trim took for the plate's own surface before) but 6 of its spacings behind
    pts, spacing, label = _plate_over_ground(height_m=2.5)
    cam = _camera()
    plain = render_points(pts, cam, WORLD, {"label": label}, spacing_m=spacing)
    trimmed = render_points(pts, cam, TRIM, {"label": label}, spacing_m=spacing)
    u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    truth = (np.abs((u - cam.cx) / cam.fx * 27.5) <= 4.0) & (np.abs((v - cam.cy) / cam.fy * 27.5) <= 4.0)
    over_plain = (plain.attributes["label"] == 1) & ~truth
    over_trim = (trimmed.attributes["label"] == 1) & ~truth
    assert over_plain.sum() > 4 * 35  # more than a pixel past every edge (the plate is 35 px across)
    # what stays lies between two of the jittered edge's samples (within a quarter spacing of the
    # segment joining them); untrimmed, every splat past the edge stayed
    assert over_trim.sum() < 0.3 * over_plain.sum()


def test_a_pole_s_samples_are_drawn_joined_in_front_of_a_wall() -> None:
    # a 6 m pole's samples every 0.5 m (3 px from 20 m, its splats 6 px across) 3 m in front of a dense
    # wall: the pixels between its samples lie along the line they make and stay the pole's, those
    # beside it (beyond a quarter of a spacing) go to the wall
    z = np.arange(0.0, 6.01, 0.5)
    pole = np.c_[np.zeros_like(z), np.zeros_like(z), z]
    g = np.arange(-10.0, 10.0, 0.05)
    wx, wz = np.meshgrid(g, g + 3.0)
    wall = np.c_[wx.ravel(), np.full(wx.size, 3.0), wz.ravel()]
    pts = np.concatenate([wall, pole]).astype(np.float32)
    spacing = np.r_[np.full(len(wall), 0.05), np.full(len(pole), 0.5)].astype(np.float32)
    label = np.r_[np.zeros(len(wall), np.uint8), np.ones(len(pole), np.uint8)]
    cam = Camera.look_at((0.0, -20.0, 3.0), (0.0, 0.0, 3.0), 120, 120, fx=120.0)
    trimmed = render_points(pts, cam, TRIM, {"label": label}, spacing_m=spacing)
    plain = render_points(pts, cam, WORLD, {"label": label}, spacing_m=spacing)
    column = int(cam.cx)
    rows = np.flatnonzero(plain.attributes["label"][:, column] == 1)
    top, bottom = int(cam.cy - 3.0 * cam.fy / 20.0), int(cam.cy + 3.0 * cam.fy / 20.0)
    assert (trimmed.attributes["label"][top:bottom, column] == 1).all()  # joined from end to end
    assert len(rows) > bottom - top
    # beside the pole the splats are trimmed: at most 3 px wide (6 px before) along its length
    width = (trimmed.attributes["label"][top:bottom] == 1).sum(axis=1)
    wide = (plain.attributes["label"][top:bottom] == 1).sum(axis=1)
    assert width.max() <= 3 and wide.min() >= 5


def test_the_trim_opens_no_hole_inside_a_surface() -> None:
    pts, spacing, label = _plate_over_ground()
    cam = _camera()
    trimmed = render_points(pts, cam, TRIM, {"label": label}, spacing_m=spacing)
    inner = slice(40, 80)
    assert (trimmed.attributes["label"][inner, inner] == 1).all()


def test_with_nothing_behind_the_trim_changes_nothing() -> None:
    pts, spacing, label = _plate_over_ground()
    plate = label == 1
    cam = _camera()
    plain = render_points(pts[plate], cam, WORLD, spacing_m=spacing[plate])
    trimmed = render_points(pts[plate], cam, TRIM, spacing_m=spacing[plate])
    assert np.array_equal(plain.index, trimmed.index) and trimmed.stats["trimmed"] == 0


def test_the_trim_does_not_depend_on_the_batch() -> None:
    pts, spacing, label = _plate_over_ground()
    cam = _camera()
    a = render_points(pts, cam, TRIM, spacing_m=spacing)
    b = render_points(
        pts,
        cam,
        RenderParams(scale=1.0, splat="world", trim_edges=True, chunk_points=1_777),
        spacing_m=spacing,
    )
    assert np.array_equal(a.index, b.index)


def test_fixed_splats_are_not_trimmed() -> None:
    pts, spacing, label = _plate_over_ground()
    cam = _camera()
    a = render_points(pts, cam, RenderParams(scale=1.0, point_size_px=3))
    b = render_points(pts, cam, RenderParams(scale=1.0, point_size_px=3, trim_edges=True))
    assert np.array_equal(a.index, b.index)
