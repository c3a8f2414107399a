"""The analytic ray caster and view truth against cases solved by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from siteline.camera.pinhole import Camera
from siteline.codes import CHANGED, IGNORE, UNCHANGED
from siteline.synth.primitives import Primitive
from siteline.synth.raycast import MISS, camera_rays, cast, ray_distances
from siteline.synth.viewtruth import SHOWN_MIN_PX, MaskScore, view_truth

F = 100.0  # focal length, pixels


def nadir(height: float, size: int = 101, x: float = 0.0, y: float = 0.0) -> Camera:
    """Straight down from ``height`` m over (x, y): image right is +x, image down is -y."""
    return Camera.look_at((x, y, height), (x, y, 0.0), size, size, F)


def ground(
    size: float = 1000.0, pit: tuple | None = None, exclude: tuple | None = None, key: str = "ground"
) -> Primitive:
    h = size / 2
    return Primitive(key, "v1", 1, 2, "terrain", ((-h, h, -h, h), (0.0, 0.0), pit, exclude), (100, 100, 100))


def box(
    cx: float, cy: float, size: tuple, yaw: float = 0.0, key: str = "box", sig: str = "v1", oid: int = 5
) -> Primitive:
    return Primitive(key, sig, oid, 6, "box", ((cx, cy, 0.0), size, yaw), (200, 0, 0))


def expected_columns(half_width_m: float, depth_m: float, size: int) -> int:
    """Pixel centres (i + 0.5) of a ``size`` px image (cx = size / 2) whose rays meet |x| <= half width."""
    u = np.arange(size) + 0.5
    return int((np.abs((u - size / 2) / F * depth_m) <= half_width_m).sum())


def test_a_box_top_seen_face_on_is_a_known_rectangle():
    # a 4.1 x 2.1 m box, 5 m tall, under a camera 25 m up: its top is 20 m away, so it spans
    # |u - cx| <= 2.05 / 20 * 100 = 10.25 px and |v - cy| <= 5.25 px: 21 x 11 pixel centres
    cam = nadir(25.0)
    prims = [ground(), box(0.0, 0.0, (4.1, 2.1, 5.0))]
    hits = cast(cam, prims)
    on_box = hits.which == 1
    assert expected_columns(2.05, 20.0, 101) == 21 and expected_columns(1.05, 20.0, 101) == 11
    rows, cols = np.nonzero(on_box)
    assert on_box.sum() == 21 * 11
    assert (rows.min(), rows.max(), cols.min(), cols.max()) == (45, 55, 40, 60)
    centre = hits.distance[50, 50]
    assert centre == pytest.approx(20.0, abs=1e-9)
    assert hits.points[50, 50] == pytest.approx([0.0, 0.0, 5.0], abs=1e-9)
    # everything else meets the ground 25 m below
    assert (hits.which[~on_box] == 0).all()
    assert hits.points[~on_box][:, 2] == pytest.approx(0.0, abs=1e-9)


def test_a_yawed_box_and_its_walls_seen_obliquely():
    # a box turned 90 degrees is the same box with its sides swapped
    cam = Camera.look_at((30.0, -30.0, 20.0), (0.0, 0.0, 2.0), 120, 90, 80.0)
    a = cast(cam, [ground(), box(0.0, 0.0, (4.0, 2.0, 5.0))])
    b = cast(cam, [ground(), box(0.0, 0.0, (2.0, 4.0, 5.0), yaw=math.pi / 2)])
    assert (a.which == b.which).all()
    assert np.allclose(a.distance[a.which == 1], b.distance[b.which == 1], atol=1e-9)
    # a wall is seen: some box hits lie below its top
    assert (a.points[a.which == 1][:, 2] < 4.99).any()


def test_sphere_cylinder_and_cone_on_the_optical_axis():
    cam = nadir(50.0)
    rays = camera_rays(cam)
    centre = 50 * 101 + 50  # the pixel whose centre lies on the optical axis (cx = 50.5)
    sphere = Primitive("s", "v1", 1, 5, "sphere", (0.0, 0.0, 10.0, 3.0), (0, 0, 0))
    cyl = Primitive("c", "v1", 1, 5, "cylinder", (0.0, 0.0, 0.0, 2.0, 7.0), (0, 0, 0))
    cone = Primitive("k", "v1", 1, 5, "cone", (0.0, 0.0, 0.0, 2.0, 6.0), (0, 0, 0))
    assert ray_distances(rays, sphere)[centre] == pytest.approx(50.0 - 13.0, abs=1e-9)
    assert ray_distances(rays, cyl)[centre] == pytest.approx(50.0 - 7.0, abs=1e-9)  # its top cap
    assert ray_distances(rays, cone)[centre] == pytest.approx(50.0 - 6.0, abs=1e-6)  # its apex
    # the sphere's disk: pixels whose ray passes within 3 m of its centre, |u - cx| / F <= tan(asin(3 / 40))
    t = ray_distances(rays, sphere).reshape(101, 101)
    half = math.tan(math.asin(3.0 / 40.0)) * F
    u = np.arange(101) + 0.5 - 50.5
    inside = (u[None, :] ** 2 + u[:, None] ** 2) <= half**2
    assert (np.isfinite(t) == inside).all()


def test_a_cylinder_seen_from_the_side_and_a_cone_half_way_down():
    cam = Camera.look_at((0.0, -20.0, 1.0), (0.0, 0.0, 1.0), 101, 101, F)
    cyl = Primitive("c", "v1", 1, 5, "cylinder", (0.0, 0.0, 0.0, 2.0, 7.0), (0, 0, 0))
    rays = camera_rays(cam)
    centre = 50 * 101 + 50
    assert ray_distances(rays, cyl)[centre] == pytest.approx(18.0, abs=1e-9)
    cone = Primitive("k", "v1", 1, 5, "cone", (0.0, 0.0, 0.0, 2.0, 2.0), (0, 0, 0))
    # at z = 1 the cone's radius is 1 m
    assert ray_distances(rays, cone)[centre] == pytest.approx(19.0, abs=1e-9)


def test_terrain_pit_floor_ramp_and_hole():
    pit = (-10.0, 10.0, -10.0, 10.0, 4.0)
    floor = Primitive(
        "pit", "d4", 2, 2, "terrain", ((-10.0, 10.0, -10.0, 10.0), (0.0, 0.0), pit, None), (0, 0, 0)
    )
    rim = ground(100.0, exclude=(-10.0, 10.0, -10.0, 10.0))
    for x, z in ((0.0, -4.0), (-9.0, -2.0), (-9.5, -1.0), (9.0, -2.0), (-20.0, 0.0)):
        hits = cast(nadir(30.0, 3, x=x, y=0.0), [rim, floor])
        assert hits.points[1, 1, 2] == pytest.approx(z, abs=1e-6), x
        assert hits.which[1, 1] == (0 if abs(x) > 10 else 1)
    # without the pit surface the rim's hole shows nothing
    hits = cast(nadir(30.0, 3), [rim])
    assert hits.which[1, 1] == MISS and not np.isfinite(hits.distance[1, 1])


def test_a_sloped_terrain_is_met_where_its_height_field_is():
    slope = Primitive(
        "g", "v1", 1, 2, "terrain", ((-50.0, 50.0, -50.0, 50.0), (0.2, 0.0), None, None), (0, 0, 0)
    )
    cam = Camera.look_at((-40.0, 0.0, 30.0), (20.0, 0.0, 0.0), 64, 48, 60.0)
    hits = cast(cam, [slope])
    got = hits.points[hits.which == 0]
    assert len(got) > 1000
    assert np.abs(got[:, 2] - 0.2 * got[:, 0]).max() < 1e-6


def test_view_truth_of_a_removed_a_moved_and_a_kept_box():
    cam = nadir(40.0, 121)
    kept = box(-12.0, 0.0, (3.0, 3.0, 2.0), key="kept", oid=1)
    first = [
        ground(),
        kept,
        box(0.0, 0.0, (4.0, 4.0, 3.0), key="removed", oid=2),
        box(10.0, 10.0, (2.0, 2.0, 2.0), key="moved", oid=3),
    ]
    second = [ground(), kept, box(12.0, 10.0, (2.0, 2.0, 2.0), key="moved", sig="v2", oid=3)]
    truth = view_truth(cam, first, second)
    ha, hb = cast(cam, first), cast(cam, second)
    removed = ha.which == 2
    moved = (ha.which == 3) | (hb.which == 2)
    assert (truth.mask[removed] == CHANGED).all()
    assert (truth.mask[moved] == CHANGED).all()
    assert (truth.mask[ha.which == 1] == UNCHANGED).all()
    assert ((truth.mask == CHANGED) == (removed | moved)).all()
    assert set(np.unique(truth.changed_object[truth.mask == CHANGED])) == {2, 3}
    assert truth.names[2] == "removed#2"


def test_view_truth_ignores_sky_ignored_classes_and_outside_the_fence():
    cam = Camera.look_at((0.0, -30.0, 10.0), (0.0, 0.0, 10.0), 60, 40, 40.0)  # level: the upper half is sky
    snow = Primitive("flake", "e1", 9, 21, "sphere", (0.0, 0.0, 10.0, 1.0), (255, 255, 255))
    g = ground(100.0)
    truth = view_truth(
        cam, [g, snow], [g], ignored_classes={21}, fence=[(-5, -50), (5, -50), (5, 50), (-5, 50), (-5, -50)]
    )
    hits = cast(cam, [g, snow])
    assert (truth.mask[hits.which == MISS] == IGNORE).all()
    assert (truth.mask[hits.which == 1] == IGNORE).all()
    outside = (hits.which == 0) & (np.abs(hits.points[..., 0]) > 5.01)
    assert outside.any() and (truth.mask[outside] == IGNORE).all()
    inside = (hits.which == 0) & (np.abs(hits.points[..., 0]) < 4.99)
    assert inside.any() and (truth.mask[inside] == UNCHANGED).all()


def test_mask_score_counts_specks_objects_and_boundaries():
    cam = nadir(40.0, 121)
    first = [ground(), box(0.0, 0.0, (8.0, 8.0, 3.0), key="removed", oid=2)]
    truth = view_truth(cam, first, [ground()])
    perfect = MaskScore()
    perfect.add(truth.mask.copy(), truth)
    assert perfect.precision == perfect.recall == perfect.f1 == 1.0
    assert perfect.boundary_f == 1.0 and perfect.specks == [0]
    assert perfect.object_recall() == {"removed#2": 1.0}
    noisy = truth.mask.copy()
    noisy[5, 5] = CHANGED  # a one-pixel speck
    noisy[100:110, 100:110] = CHANGED  # a 100 px false region: no speck
    ys, xs = np.nonzero(truth.mask == CHANGED)
    noisy[ys.max() + 1, xs.min() + 3 : xs.min() + 6] = CHANGED  # an edge drawn one pixel too far: a rim piece
    half = truth.mask == CHANGED
    rows = np.nonzero(half.any(axis=1))[0]
    noisy[rows[: len(rows) // 2]] = np.where(
        half[rows[: len(rows) // 2]], UNCHANGED, noisy[rows[: len(rows) // 2]]
    )
    s = MaskScore()
    s.add(noisy, truth)
    assert s.specks == [1] and s.rims == [1]
    assert s.fp == 104
    assert s.object_recall()["removed#2"] == pytest.approx(0.5, abs=0.05)
    assert 0 < s.boundary_f < 1
    # the views that show each changed object, and the share of its pixels the mask ignores
    assert s.object_views() == {"removed#2": 1} and s.object_ignored() == {"removed#2": 0.0}
    # the half whose rows were labelled unchanged is what lies behind labelled in its place
    assert s.object_through()["removed#2"] == pytest.approx(0.5, abs=0.05)
    hidden = truth.mask.copy()
    hidden[rows[: len(rows) // 4]] = np.where(
        half[rows[: len(rows) // 4]], IGNORE, hidden[rows[: len(rows) // 4]]
    )
    s.add(hidden, truth)
    assert s.object_views() == {"removed#2": 2}
    assert s.object_ignored()["removed#2"] == pytest.approx(0.125, abs=0.03)
    assert s.object_through()["removed#2"] == pytest.approx(0.25, abs=0.03)  # 0.5 of one view, 0 of the other
    tiny = view_truth(nadir(400.0, 121), first, [ground()])  # the box on a few pixels: not shown
    n_px = int((tiny.mask == CHANGED).sum())
    assert 0 < n_px < SHOWN_MIN_PX
    s.add(tiny.mask.copy(), tiny)
    assert s.object_views() == {"removed#2": 2} and s.to_dict()["object_views"] == {"removed#2": 2}
    # an edge drawn a pixel past a change the mask ignores is a rim piece of that change, not a speck
    ignored_edge = truth.mask.copy()
    ignored_edge[truth.mask == CHANGED] = IGNORE
    ignored_edge[ys.max() + 1, xs.min() + 3 : xs.min() + 6] = CHANGED
    edge = MaskScore()
    edge.add(ignored_edge, truth)
    assert edge.fp == 3 and edge.specks == [0] and edge.rims == [1] and edge.rim_px == 3


def test_a_surface_that_hardly_moved_is_not_changed_where_it_did_not():
    # a pit deepened from 2 to 4 m: its floor moved 2 m, the rim of its ramps by less than 5 cm
    rect = (-10.0, 10.0, -10.0, 10.0)
    before = Primitive("pit", "d2", 2, 2, "terrain", (rect, (0.0, 0.0), (*rect, 2.0), None), (0, 0, 0))
    after = Primitive("pit", "d4", 2, 2, "terrain", (rect, (0.0, 0.0), (*rect, 4.0), None), (0, 0, 0))
    rim = ground(100.0, exclude=rect)
    cam = nadir(30.0, 201)
    truth = view_truth(cam, [rim, before], [rim, after])
    hits = cast(cam, [rim, before])
    x = np.abs(hits.points[..., 0])
    y = np.abs(hits.points[..., 1])
    edge = 10.0 - np.maximum(x, y)  # metres inside the pit's edge: the change there is edge x 1 m
    assert (truth.mask[(hits.which == 1) & (edge > 0.1)] == CHANGED).all()
    assert (truth.mask[(hits.which == 1) & (edge < 0.04)] == UNCHANGED).all()
    assert (truth.mask[hits.which == 0] == UNCHANGED).all()
