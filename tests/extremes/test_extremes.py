"""Numerical extremes across stages: each gives an exact result or a clear error, never NaN and never
a silent wrong answer."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

from siteline.camera.pinhole import Camera
from siteline.errors import PointCloudError, RegistrationError, ViewsError
from siteline.labels.change import CHANGED, IGNORED, change_flags
from siteline.pointpass import TilingResources, write_las
from siteline.records.params.render import RenderParams
from siteline.register.georegister import check_spread
from siteline.register.icp import point_to_plane_icp
from siteline.render.georef import render_georeferenced
from siteline.render.zbuffer import render_points
from siteline.site.spec import make_site_spec
from siteline.site.taxonomy import default_taxonomy
from siteline.tiles.reader import SceneTiles
from siteline.tiles.writer import TileInput, write_tiles
from siteline.views.ground import fit_ground_plane

IGN = default_taxonomy().ignored_lut()
EXTREME_ORIGINS = [
    ((445_000.0, 5_030_000.0, 80.0), "EPSG:32618"),
    ((500_000.0, 9_999_500.0, 4_000.0), "EPSG:32618"),  # near 1e7 m, high altitude
    ((-8_400_000.0, -4_500_000.0, -400.0), "EPSG:3857"),  # negative everything
]


def _grid(n_side=60, step=0.25):
    q = 1.0 / 1024  # dyadic, exact in float32 and after adding an integer origin in float64
    g = np.arange(n_side) * step
    xx, yy = np.meshgrid(g - g.mean(), g - g.mean())
    z = np.round(0.3 * np.sin(xx) / q) * q
    return np.c_[np.round(xx.ravel() / q) * q, np.round(yy.ravel() / q) * q, z.ravel()]


@pytest.mark.parametrize(("origin", "crs"), EXTREME_ORIGINS)
def test_render_is_exact_at_every_origin(origin, crs) -> None:
    local = _grid()
    cam = Camera.look_at((0.0, -20.0, 15.0), (0.0, 0.0, 0.0), 200, 150, fx=180.0)
    ref = render_points(local.astype(np.float32), cam, RenderParams(scale=1.0))
    geo = render_georeferenced(local + np.asarray(origin), origin, cam, RenderParams(scale=1.0))
    assert np.array_equal(ref.index, geo.index) and np.array_equal(ref.depth, geo.depth, equal_nan=True)
    assert ref.hit.any() and not np.isnan(ref.depth[ref.hit]).any()


@pytest.mark.parametrize(("origin", "crs"), EXTREME_ORIGINS)
@pytest.mark.parametrize("scale", [1e-7, 1e-4, 1e-3, 1e-2, 1.0])
def test_tiles_round_trip_every_las_scale_and_origin(tmp_path, origin, crs, scale) -> None:
    rng = np.random.default_rng(1)
    extent = 20.0 if scale == 1e-7 else 150.0  # 1e-7 m counts reach only +-214 m around the offset
    local = np.c_[rng.uniform(-extent, extent, (3000, 2)), rng.uniform(-5, 5, 3000)]
    write_las(
        tmp_path / "c.las",
        local + np.asarray(origin),
        crs=crs,
        gps_time=np.arange(3000.0),
        classification=np.full(3000, 2, np.uint8),
        scale=scale,
    )
    import laspy

    las = laspy.read(tmp_path / "c.las")
    geo = np.c_[las.x, las.y, las.z]
    site = make_site_spec("x", crs, origin)
    r = write_tiles(
        TileInput(tmp_path / "c.las", site, pyproj.CRS(crs)),
        tmp_path / "s.zarr",
        resources=TilingResources(workers=1),
    )
    t = SceneTiles.open(r.uri)
    data = t.read({k: t.prefix(k) for k in t.by_tile}, ("gps_time",))
    back = data.xyz_m + np.asarray(origin)
    err = np.abs(back - geo[data.attributes["gps_time"].astype(int)])
    assert np.isfinite(err).all() and err.max() <= 0.0005 + 1e-9


def test_zero_one_and_duplicated_points() -> None:
    cam = Camera.look_at((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), 32, 32, fx=16.0)
    s = RenderParams(scale=1.0)
    zero = render_points(np.zeros((0, 3), np.float32), cam, s)
    assert not zero.hit.any() and np.isnan(zero.depth).all()
    one = render_points(np.zeros((1, 3), np.float32), cam, s)
    assert one.hit.sum() == 1 and one.depth[one.hit][0] == 10.0
    dup = render_points(np.zeros((5, 3), np.float32), cam, s)
    assert dup.hit.sum() == 1 and dup.index[dup.hit][0] == 0  # ties go to the smallest index
    a = np.zeros((3, 3))
    cls = np.array([1, 1, 10], np.uint8)
    assert change_flags(a, cls, np.zeros((0, 3)), np.zeros(0, np.uint8), 0.5, IGN).tolist() == [
        CHANGED,
        CHANGED,
        IGNORED,
    ]
    assert change_flags(np.zeros((0, 3)), np.zeros(0, np.uint8), a, cls, 0.5, IGN).shape == (0,)
    assert change_flags(a, cls, a, cls, 0.5, IGN).tolist() == [0, 0, IGNORED]
    with pytest.raises(ViewsError, match="at least 3"):
        fit_ground_plane(np.zeros((2, 3)))
    with pytest.raises(ViewsError):
        fit_ground_plane(np.zeros((50, 3)))  # fifty copies of one point: no plane


def test_one_point_and_empty_clouds_through_tiles_and_ingest(tmp_path) -> None:
    from siteline.ingest.pointcloud import scan_las

    site = make_site_spec("x", "EPSG:32618", (445_000.0, 5_030_000.0, 80.0))
    write_las(tmp_path / "one.las", np.array([[445_001.0, 5_030_002.0, 81.0]]), crs="EPSG:32618")
    r = write_tiles(
        TileInput(tmp_path / "one.las", site, pyproj.CRS("EPSG:32618")),
        tmp_path / "one.zarr",
        resources=TilingResources(workers=1),
    )
    pts = SceneTiles.open(r.uri).points(attributes=())
    assert pts.xyz_m.tolist() == [[1.0, 2.0, 1.0]]
    write_las(tmp_path / "empty.las", np.zeros((0, 3)), crs="EPSG:32618")
    with pytest.raises(PointCloudError, match="no points"):
        scan_las(tmp_path / "empty.las", site)


@pytest.mark.parametrize("distance_m", [1e-3, 10_000.0])
def test_cameras_very_near_and_very_far(distance_m) -> None:
    step = distance_m / 40 if distance_m < 1 else 200.0  # the view spans 2x the distance; ~80 points across
    g = (np.arange(200) - 99.5) * step
    xx, yy = np.meshgrid(g, g)
    plane = np.c_[xx.ravel(), yy.ravel(), np.zeros(xx.size)]
    cam = Camera.look_at((0.0, 0.0, distance_m), (0.0, 0.0, 0.0), 64, 48, fx=32.0)
    r = render_points(plane.astype(np.float32), cam, RenderParams(scale=1.0, near_m=distance_m / 10))
    assert r.hit.mean() > 0.9
    assert np.abs(r.depth[r.hit] - distance_m).max() <= 1e-5 * distance_m
    # at the default 1 mm near plane, a surface 1 mm away is exactly on it and is (explicitly) dropped
    if distance_m == 1e-3:
        assert not render_points(plane.astype(np.float32), cam, RenderParams(scale=1.0)).hit.any()


def test_grazing_view() -> None:
    plane = _grid(n_side=300, step=0.2)
    plane[:, 2] = 0.0
    ang = np.deg2rad(89.9)
    target = np.array([0.0, 20.0, 0.0])
    cam = Camera.look_at(
        target - 30.0 * np.array([0.0, np.sin(ang), -np.cos(ang)]), target, 128, 96, fx=100.0
    )
    r = render_points(plane.astype(np.float32), cam, RenderParams(scale=1.0))
    assert r.hit.any() and np.isfinite(r.depth[r.hit]).all() and (r.depth[r.hit] > 0).all()


def test_collinear_and_too_few_cameras_are_refused() -> None:
    line = np.c_[np.linspace(0, 100, 8), np.zeros(8), np.full(8, 80.0)]
    with pytest.raises(RegistrationError, match="collinear"):
        check_spread([f"i{i}" for i in range(8)], line, "model")
    with pytest.raises(RegistrationError, match="at least 3"):
        check_spread(["a", "b"], line[:2], "model")
    same = np.tile([1.0, 2.0, 3.0], (5, 1))
    with pytest.raises(RegistrationError):
        check_spread([f"i{i}" for i in range(5)], same, "model")


def test_flat_scene_icp_is_finite_and_flagged() -> None:
    rng = np.random.default_rng(0)
    flat = np.c_[rng.uniform(-50, 50, (20000, 2)), rng.normal(0, 0.01, 20000)]
    res = point_to_plane_icp(flat + [3.0, -2.0, 0.07], flat)
    assert res.degenerate
    vals = [res.residual_m, res.translation_m, res.rotation_deg, *np.ravel(res.correction)]
    assert np.isfinite(vals).all()
    assert abs(np.array(res.correction)[2, 3] + 0.07) < 0.01  # the constrained direction is right
    empty = point_to_plane_icp(np.zeros((0, 3)), flat)
    assert empty.degenerate and empty.residual_m == np.inf and empty.matched == 0
    # too few points to align: the correction is the identity and nothing matched
    assert empty.correction == np.eye(4).tolist() and empty.matched == 0


def test_content_seed_ignores_the_origins_last_bits() -> None:
    """The level-of-detail seed of a scan whose bound is -65.005 m is the same whether the site-local
    float came out a hair above or below it (what a (1000, 2000) and a (-8.4e6, 5.6e6) origin give for
    the same LAS); a bound that really moves by a millimetre changes it."""
    from dataclasses import replace

    from siteline.records.scan import LasScan

    def scan(y_min: float) -> LasScan:
        return LasScan(
            path="cloud.las", source_crs="EPSG:3857", transformed=False, point_count=213_521,
            bounds_min=[-80.0, y_min, -2.021], bounds_max=[79.997, 65.01, 44.237],
            class_histogram={"ground": 10}, unknown_codes={}, outside_fence=0, colour="rgb 16-bit",
            density_pts_m2=10.26, version="1.2", point_format=3, scale=[0.001] * 3, offset=[0.0] * 3,
            gps_time_range=[1.0, 2.0], z_unit={"name": "metre"}, creation_date=None,
        )  # fmt: skip

    small, large = scan(-65.00500000000011), scan(-65.00499999988824)
    assert small.content_seed() == large.content_seed()
    assert replace(small, bounds_min=[-80.0, -65.006, -2.021]).content_seed() != small.content_seed()
