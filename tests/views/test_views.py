"""Synthetic views: ground fit, the three strategies, rejection and stratified sampling."""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree

from siteline.camera.pinhole import Camera
from siteline.errors import ViewsError
from siteline.records.pairs import ViewStrategy
from siteline.records.params.views import ViewParams
from siteline.site.fence import inside_fence
from siteline.views.generate import (
    SPARSE_SAMPLE,
    NamedCamera,
    SyntheticView,
    candidate_views,
    generate_views,
    probe,
    sparse_share,
    stratified_sample,
)
from siteline.views.ground import GroundPlane, fit_ground_plane
from siteline.views.sources import ArrayPointSource
from siteline.views.strategies import mirror

FENCE = [(-40.0, -40.0), (40.0, -40.0), (40.0, 40.0), (-40.0, 40.0)]
PARAMS = ViewParams(scale=0.25, depth_probe_scale=0.25, min_coverage=0.3, views=40)


def _scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    ground = np.c_[rng.uniform(-70, 70, (60000, 2)), rng.normal(0.0, 0.02, 60000)]
    building = np.c_[rng.uniform(-8, 8, (8000, 2)), rng.uniform(0, 12, 8000)]
    xyz = np.concatenate([ground, building]).astype(np.float32)
    cls = np.r_[np.ones(len(ground)), np.full(len(building), 2)].astype(np.uint8)
    return xyz, cls


def _real_cameras() -> list[NamedCamera]:
    cams = []
    for i, (x, y) in enumerate([(-55, 0), (55, 10), (0, -55), (20, 55)]):
        cams.append(
            NamedCamera(
                f"DJI_{i:04d}.JPG", Camera.look_at((x, y, 40.0), (0.3 * x, 0.3 * y, 0.0), 320, 240, fx=260.0)
            )
        )
    return cams


def test_ground_plane_is_robust_to_outliers() -> None:
    rng = np.random.default_rng(0)
    xy = rng.uniform(-50, 50, (5000, 2))
    z = 0.02 * xy[:, 0] - 0.01 * xy[:, 1] + 3.0 + rng.normal(0, 0.02, len(xy))
    pts = np.c_[xy, z]
    outliers = np.c_[rng.uniform(-50, 50, (2000, 2)), rng.uniform(5, 30, 2000)]
    plane = fit_ground_plane(np.concatenate([pts, outliers]))
    true_n = np.array([-0.02, 0.01, 1.0]) / np.linalg.norm([-0.02, 0.01, 1.0])
    assert np.degrees(np.arccos(np.clip(np.dot(plane.normal, true_n), -1, 1))) < 0.2
    assert abs(plane.height(np.array([0.0, 0.0, 3.0]))) < 0.02


def test_ground_plane_needs_points() -> None:
    with pytest.raises(ViewsError, match="at least 3"):
        fit_ground_plane(np.zeros((2, 3)))


def test_thirty_two_candidates_per_real_camera() -> None:
    xyz, cls = _scene()
    plane = fit_ground_plane(xyz[cls == 1])
    source = ArrayPointSource(xyz)
    for cam in _real_cameras():
        cands = candidate_views(cam, plane, FENCE, lambda c: 30.0, ViewParams())
        assert len(cands) == 32
        assert len({v.strategy for v in cands}) == 32
        assert all(v.parent == cam.name for v in cands)
    assert (
        len(candidate_views(_real_cameras()[0], plane, None, lambda c: 30.0, ViewParams(mirror=False))) == 16
    )
    assert source.nearest_within(np.zeros((1, 3)), 1.0)[0] < 1.0
    assert source.nearest_within(np.array([[0.0, 0.0, 500.0]]), 1.0)[0] == np.inf  # none that near


def test_mirroring_twice_gives_the_original() -> None:
    cam = _real_cameras()[0].camera
    once, seg = mirror(cam, FENCE, rule="reflect")
    twice, seg2 = mirror(once, FENCE, rule="reflect")
    assert seg == seg2
    assert np.allclose(twice.R, cam.R, atol=1e-12) and np.allclose(twice.center, cam.center, atol=1e-9)
    assert inside_fence(once.center[None, :2], FENCE)[0]
    assert np.linalg.det(once.R) == pytest.approx(1.0)
    # the mirrored camera looks back across the fence: its forward x flips sign
    assert np.sign(once.forward[0]) == -np.sign(cam.forward[0])


def test_vertical_heights_are_fractions_of_the_real_height() -> None:
    xyz, cls = _scene()
    plane = fit_ground_plane(xyz[cls == 1])
    cam = _real_cameras()[0]
    cands = candidate_views(cam, plane, FENCE, lambda c: 30.0, ViewParams())
    h0 = plane.height(cam.camera.center)
    for v in cands:
        if not v.params.mirrored and v.params.forward_fraction == 0:
            assert plane.height(v.camera.center) == pytest.approx(v.params.vertical_fraction * h0, abs=1e-9)
            assert np.allclose(v.camera.R, cam.camera.R)


def test_generated_views_are_valid_seeded_and_recorded() -> None:
    xyz, cls = _scene()
    plane = fit_ground_plane(xyz[cls == 1])
    source = ArrayPointSource(xyz)
    a = generate_views(_real_cameras(), plane, FENCE, source, PARAMS)
    b = generate_views(_real_cameras(), plane, FENCE, source, PARAMS)
    assert a.candidates == 4 * 32
    assert 0 < len(a.views) <= 40
    assert [v.to_dict() for v in a.views] == [v.to_dict() for v in b.views]
    assert [v.index for v in a.views] == list(range(len(a.views)))
    for v in a.views:
        assert plane.height(v.camera.center) >= PARAMS.min_height_m
        assert cKDTree(xyz).query(v.camera.center)[0] >= PARAMS.clearance_m
        assert v.coverage is not None and v.coverage >= PARAMS.min_coverage
        if v.params.mirrored:
            assert inside_fence(v.camera.center[None, :2], FENCE)[0]
        again = SyntheticView.from_dict(v.to_dict())
        assert again.camera == v.camera and again.parent == v.parent
    assert {v.params.mirrored for v in a.views} == {False, True}
    c = generate_views(
        _real_cameras(),
        plane,
        FENCE,
        source,
        ViewParams(
            **{
                **PARAMS.to_dict(),
                "seed": 1,
                "vertical_fractions": (1.0, 0.75, 0.5, 0.25),
                "forward_fractions": (0.0, 0.25, 0.5, 0.75),
            }
        ),
    )
    assert [v.to_dict() for v in c.views] != [v.to_dict() for v in a.views]


def test_views_under_geometry_and_underground_are_rejected() -> None:
    xyz, cls = _scene()
    slab = np.c_[np.random.default_rng(1).uniform(-60, -50, (2000, 2)), np.full(2000, 60.0)].astype(
        np.float32
    )
    xyz = np.concatenate([xyz, slab])
    plane = fit_ground_plane(xyz[:60000])
    source = ArrayPointSource(xyz)
    under = NamedCamera("under", Camera.look_at((-55, -55, 40.0), (0, 0, 0), 320, 240, fx=260.0))
    cands = candidate_views(
        under, plane, None, lambda c: 30.0, ViewParams(mirror=False, forward_fractions=(0.0,))
    )
    from siteline.views.generate import reject

    cands = reject(cands, plane, None, source, ViewParams(mirror=False, forward_fractions=(0.0,)))
    assert {v.rejected for v in cands} == {"under_geometry"}
    below = NamedCamera("below", Camera.look_at((0, 0, -5.0), (10, 0, -5.0), 320, 240, fx=260.0))
    cands = candidate_views(
        below, plane, None, lambda c: 30.0, ViewParams(mirror=False, forward_fractions=(0.0,))
    )
    cands = reject(cands, plane, None, source, ViewParams(mirror=False, forward_fractions=(0.0,)))
    assert {v.rejected for v in cands} == {"underground"}


def _fake(strategy: str, i: int) -> SyntheticView:
    return SyntheticView(
        f"p{i}", strategy, ViewStrategy(1.0, False, 0.0), Camera.look_at((0, 0, 10), (0, 0, 0), 4, 4, 2.0)
    )


def test_sample_is_stratified() -> None:
    sizes = {"a": 50, "b": 3, "c": 20, "d": 9}
    views = [_fake(k, i) for k, n in sizes.items() for i in range(n)]
    for n in (10, 30, 60, 200):
        chosen = stratified_sample(views, n, seed=7)
        assert len(chosen) == min(n, len(views))
        counts = Counter(v.strategy for v in chosen)
        exhausted = {k for k in sizes if counts[k] == sizes[k]}
        open_counts = [counts[k] for k in sizes if k not in exhausted]
        if open_counts:
            assert max(open_counts) - min(open_counts) <= 1
            assert all(counts[k] <= max(open_counts) for k in exhausted)
    assert [id(v) for v in stratified_sample(views, 30, 3)] == [
        id(v) for v in stratified_sample(views, 30, 3)
    ]


def _ring_at(origin: tuple[float, float]) -> list[tuple[float, float]]:
    """The synthetic fence written in the site CRS at ``origin`` and read back to site-local metres."""
    import json

    from siteline.site.fence import fence_geojson, load_fence_geojson
    from siteline.synth.model import FENCE_M

    ring = [[x * 1.1 + 0.123456789, y * 0.9 - 0.987654321] for x, y in FENCE_M]  # not dyadic
    doc = fence_geojson(ring, (*origin, 0.0))
    return [tuple(v) for v in load_fence_geojson_doc(json.dumps(doc), origin, load_fence_geojson)]


def load_fence_geojson_doc(text: str, origin, loader):  # noqa: ANN001, ANN201
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "fence.geojson"
        path.write_text(text)
        return loader(path, (*origin, 0.0))


def test_candidate_on_a_fence_segment_gets_one_verdict_at_both_magnitudes() -> None:
    small, large = _ring_at((1000.0, 2000.0)), _ring_at((-8_400_000.0, 5_600_000.0))
    assert small != large  # the origin round trip leaves ~1e-9 m differences in the vertices
    a, b = np.asarray(small[0]), np.asarray(small[1])
    normal = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
    on = np.array([a + t * (b - a) for t in np.linspace(0.05, 0.95, 19)])
    noisy = np.concatenate([on, on + 1e-6 * normal, on - 1e-6 * normal])
    for ring in (small, large):
        assert inside_fence(noisy, ring).all()  # within LENGTH_TOL_M of the fence: inside
    for ring in (small, large):  # 1 cm is no longer on the fence: one side in, the other out
        inside_a = inside_fence(on + 0.01 * normal, ring)
        inside_b = inside_fence(on - 0.01 * normal, ring)
        assert (inside_a ^ inside_b).all()
        assert np.array_equal(inside_a, inside_fence(on + 0.01 * normal, small))


def test_mirror_of_a_camera_above_the_fence_is_kept_at_both_magnitudes() -> None:
    from siteline.views.strategies import mirror

    for ring in (_ring_at((1000.0, 2000.0)), _ring_at((-8_400_000.0, 5_600_000.0))):
        a, b = np.asarray(ring[0]), np.asarray(ring[1])
        c = (a + b) / 2
        cam = Camera.look_at((c[0], c[1], 40.0), (c[0] + 5.0, c[1] + 5.0, 0.0), 64, 48, 50.0)
        mirrored, _ = mirror(cam, ring, GroundPlane((0.0, 0.0, 1.0), 0.0))
        assert inside_fence(mirrored.center[None, :2], ring)[0]


def test_removing_one_candidate_changes_at_most_one_sampled_view() -> None:
    strategies_ = [f"v{v}-{m}-f{f}" for v in (1, 0.5) for m in ("orig", "mirror") for f in (0, 0.5)]
    pool = [
        SyntheticView(f"IMG_{p:04d}.JPG", s, ViewStrategy(1.0, False, 0.0), _fake(s, p).camera)
        for p in range(12)
        for s in strategies_
    ]
    ident = [(v.parent, v.strategy) for v in pool]
    for n in (10, 40, 90):
        base = {(v.parent, v.strategy) for v in stratified_sample(pool, n, seed=3)}
        for i in range(0, len(pool), 7):
            rest = pool[:i] + pool[i + 1 :]
            again = {(v.parent, v.strategy) for v in stratified_sample(rest, n, seed=3)}
            if ident[i] in base:
                assert len(base - again) == 1 and len(again - base) <= 1
            else:
                assert again == base


def test_sample_order_does_not_depend_on_pool_order() -> None:
    pool = [_fake(s, i) for s in ("a", "b", "c") for i in range(10)]
    one = stratified_sample(pool, 12, seed=1)
    two = stratified_sample(list(reversed(pool)), 12, seed=1)
    assert [(v.parent, v.strategy) for v in one] == [(v.parent, v.strategy) for v in two]


@pytest.mark.parametrize("pitch_deg", [-20.0, -35.0, -50.0, -70.0])
def test_mirrored_views_of_a_camera_outside_the_fence_look_into_the_site(pitch_deg: float) -> None:
    from siteline.camera.dji import cam_from_world_rotation
    from siteline.views.strategies import ground_target

    ground = GroundPlane((0.0, 0.0, 1.0), 0.0)
    hits_reflect = 0
    for yaw_deg in range(0, 360, 30):
        R = cam_from_world_rotation(float(yaw_deg), pitch_deg, 0.0)
        cam = Camera.from_pose(64, 48, 50.0, 50.0, 32.0, 24.0, R, -R @ np.array([10.0, -55.0, 40.0]))
        aimed, _ = mirror(cam, FENCE, ground)
        assert inside_fence(aimed.center[None, :2], FENCE)[0]
        target = ground_target(aimed, ground)
        assert target is not None and inside_fence(target[None, :2], FENCE)[0], yaw_deg  # looks into the site
        assert np.linalg.det(aimed.R) == pytest.approx(1.0)
        reflected, _ = mirror(cam, FENCE, rule="reflect")
        t = ground_target(reflected, ground)
        hits_reflect += t is not None and bool(inside_fence(t[None, :2], FENCE)[0])
    if (
        pitch_deg > -40
    ):  # oblique views: the reflect rule sends some axes out of the site; aim-site never does
        assert hits_reflect < 12


def test_mirror_rule_is_recorded_in_the_view_parameters() -> None:
    cams = _real_cameras()[:1]
    cands = candidate_views(cams[0], GroundPlane((0.0, 0.0, 1.0), 0.0), FENCE, lambda c: 30.0, ViewParams())
    rules = {v.params.mirror_rule for v in cands if v.params.mirrored}
    assert rules == {"aim-site"}
    assert {v.params.mirror_rule for v in cands if not v.params.mirrored} == {None}
    assert ViewParams(mirror_rule="reflect").to_dict()["mirror_rule"] == "reflect"
    with pytest.raises(ViewsError, match="mirror_rule"):
        ViewParams(mirror_rule="sideways")


def test_sparse_share_weighs_each_point_by_the_pixels_its_spacing_spans() -> None:
    """Ground points 0.5 m apart under a nadir camera of focal 200 px: 10 px apart from 10 m up,
    2 px apart from 50 m; a mixed set weighs each part by its pixels."""
    g = np.arange(-20.0, 20.0, 0.5)
    xy = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    xyz = np.c_[xy, np.zeros(len(xy))]
    spacing = np.full(len(xyz), 0.5)
    low = Camera.look_at((0, 0, 10.0), (0, 0, 0), 200, 200, fx=200.0)
    high = Camera.look_at((0, 0, 50.0), (0, 0, 0), 200, 200, fx=200.0)
    assert sparse_share(xyz, spacing, low, 1.0, 8.0) == 1.0
    assert sparse_share(xyz, spacing, low, 1.0, 10.5) == 0.0
    assert sparse_share(xyz, spacing, low, 0.5, 8.0) == 0.0  # 5 px apart at half the scale
    assert sparse_share(xyz, spacing, high, 1.0, 8.0) == 0.0
    # half the points stand for 4x the spacing: 16x the pixels each
    mixed = np.where(np.arange(len(xyz)) % 2 == 0, 0.5, 2.0)
    assert sparse_share(xyz, mixed, high, 1.0, 4.0) == pytest.approx(16 / 17, abs=0.01)
    assert sparse_share(xyz[:0], spacing[:0], low, 1.0, 8.0) == 0.0  # nothing in the frame
    # a cloud past SPARSE_SAMPLE points is judged on every k-th: the share it would have, within 0.01
    rng = np.random.default_rng(1)
    big = np.c_[rng.uniform(-20, 20, (3 * SPARSE_SAMPLE, 2)), np.zeros(3 * SPARSE_SAMPLE)]
    mixed_big = rng.choice([0.3, 1.0], len(big))
    every = sparse_share(big, mixed_big, high, 1.0, 4.0)
    px = mixed_big * 200.0 / 50.0
    assert every == pytest.approx((px[px > 4] ** 2).sum() / (px**2).sum(), abs=0.01)


def test_views_that_draw_their_surface_from_sparse_points_are_rejected() -> None:
    """A probe whose points stand for 0.5 m each: the camera 10 m up sees them 12 px apart at the
    render scale and is rejected as sparse_points; 40 m up, 3 px: kept; max_spacing_px 0 keeps both."""
    g = np.arange(-30.0, 30.0, 0.5)
    xy = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    xyz = np.c_[xy, np.zeros(len(xy))].astype(np.float32)
    source = ArrayPointSource(xyz, np.full(len(xyz), 0.5, np.float32))
    params = ViewParams(scale=1.0, splat="world", min_coverage=0.0, max_spacing_px=8.0)
    strategy = ViewStrategy(1.0, False, 0.0)
    view = {
        h: SyntheticView(
            "p", "v1-orig-f0", strategy, Camera.look_at((0, 0, h), (0, 0, 0), 240, 240, fx=240.0)
        )
        for h in (10.0, 40.0)
    }
    assert probe(view[10.0], source, params).rejected == "sparse_points"
    assert probe(view[40.0], source, params).rejected is None
    assert probe(view[10.0], source, replace(params, max_spacing_px=0.0)).rejected is None
    with pytest.raises(ViewsError, match="max_spacing_px"):
        ViewParams(max_spacing_px=-1.0)
