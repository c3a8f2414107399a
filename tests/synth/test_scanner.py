"""The airborne scanner (siteline.synth.scanner): density as asked, walls sampled by how the lines face
them, nothing where no line sees, flights that differ epoch to epoch, leaves that move, noise along
the ray."""

from __future__ import annotations

import math

import numpy as np
import pytest

from siteline.errors import SynthError
from siteline.synth import model as m
from siteline.synth.lidar import LidarSpec
from siteline.synth.primitives import Primitive, terrain_height
from siteline.synth.scanner import FLIGHTS, VARIATION, Flight, epoch_flight, fly_epoch


def _fly(
    layout: str, e: int, density: float, flight: Flight | None = None, seed: int = 0
) -> dict[str, np.ndarray]:
    site = m.SiteModel(seed=seed, n_epochs=2, layout=layout, snow_epochs=(), projection_error_epochs=())
    flight = flight if flight is not None else epoch_flight(layout, seed, e)
    chunks = list(fly_epoch(site, e, LidarSpec(density_pts_m2=density), flight))
    return {
        "xyz": np.concatenate([c.xyz for c in chunks]),
        "oid": np.concatenate([c.object_id for c in chunks]),
        "gps": np.concatenate([c.gps_time for c in chunks]),
    }


@pytest.fixture(scope="module")
def slope() -> list[dict[str, np.ndarray]]:
    return [_fly("slope", e, 20.0) for e in (0, 1)]


def test_open_ground_is_sampled_at_the_density_asked(slope) -> None:
    x0, x1, y0, y1 = m.SLOPE_TERRAIN_M
    ground = slope[0]["xyz"][slope[0]["oid"] == 1]
    # the fence's inside, away from every object: the lines' overlap gives the density on average
    box = (ground[:, 0] > -40) & (ground[:, 0] < -25) & (ground[:, 1] > 15) & (ground[:, 1] < 30)
    assert box.sum() / (15 * 15) == pytest.approx(20.0, rel=0.15)
    assert len(slope[0]["xyz"]) / ((x1 - x0) * (y1 - y0)) == pytest.approx(20.0, rel=0.1)


def _building_frame(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plan coordinates (metres) along and across the sloped layout's building (centre (-18, 8),
    turned 0.15 rad)."""
    yaw = 0.15
    rel = xyz[:, :2] - np.array([-18.0, 8.0])
    return rel @ np.array([math.cos(yaw), math.sin(yaw)]), rel @ np.array([-math.sin(yaw), math.cos(yaw)])


def test_walls_are_sampled_by_how_squarely_the_lines_face_them(slope) -> None:
    b = slope[0]["xyz"][slope[0]["oid"] == 100]
    u, v = _building_frame(b)
    roof = b[:, 2] > b[:, 2].max() - 0.2
    across = (np.abs(np.abs(v) - 5.0) < 0.1) & ~roof  # faces whose normal points across the ~20 degree lines
    along = (np.abs(np.abs(u) - 7.0) < 0.1) & ~roof
    density = {k: n / a for k, n, a in (("roof", roof.sum(), 140.0), ("across", across.sum(), 2 * 14 * 8.0),
                                        ("along", along.sum(), 2 * 10 * 8.0))}  # fmt: skip
    assert density["roof"] > 2.5 * density["across"] > 2.5 * density["along"] > 0, density


def test_what_no_line_sees_has_no_points(slope) -> None:
    # the ground under the building and under the car
    g = slope[0]["xyz"][slope[0]["oid"] == 1]
    u, v = _building_frame(g)
    assert ((np.abs(u) < 6.5) & (np.abs(v) < 4.5)).sum() == 0
    under_car = (np.abs(g[:, 0] + 5.0) < 2.0) & (np.abs(g[:, 1] + 18.0) < 0.7)
    assert under_car.sum() == 0
    # every return lies on the epoch's surfaces (within the range noise)
    ground_z = terrain_height(g[:, 0], g[:, 1], m.SLOPE_GRADE, None)
    assert np.abs(g[:, 2] - ground_z).max() < 6 * FLIGHTS["slope"].noise_m
    assert np.std(g[:, 2] - ground_z) == pytest.approx(FLIGHTS["slope"].noise_m, rel=0.2)


def test_each_epoch_flies_other_lines_and_the_same_seed_the_same_points(slope) -> None:
    a, b = epoch_flight("slope", 0, 0), epoch_flight("slope", 0, 1)
    assert (a.heading_deg, a.offset_m, a.altitude_m) != (b.heading_deg, b.offset_m, b.altitude_m)
    plan = FLIGHTS["slope"]
    for f in (a, b):
        assert abs(f.heading_deg - plan.heading_deg) <= VARIATION[0]
        assert abs(f.offset_m - plan.offset_m) <= VARIATION[1]
        assert abs(f.altitude_m - plan.altitude_m) <= VARIATION[2]
    assert epoch_flight("slope", 0, 1, variation=0.0) == plan
    again = _fly("slope", 0, 20.0)
    assert np.array_equal(again["xyz"], slope[0]["xyz"])
    # the unchanged building sampled at other places: hardly a point of one epoch on a point of the other
    p, q = (s["xyz"][s["oid"] == 100] for s in slope)
    from scipy.spatial import cKDTree

    d, _ = cKDTree(q).query(p)
    assert np.median(d) > 0.02
    # times run forward along each line, the lines one after another
    assert np.all(np.diff(np.sort(slope[0]["gps"])) >= 0) and np.ptp(slope[0]["gps"]) > 30


def test_a_canopy_returns_from_inside_its_crown_and_lets_some_pulses_through(slope) -> None:
    crown = next(p for p in m.slope_scene(0) if p.kind == "canopy")
    cx, cy, cz, r, depth = crown.params
    leaves = [s["xyz"][s["oid"] == 800] for s in slope]
    for pts in leaves:
        top = pts[pts[:, 2] > cz + 1.0]  # the crown's upper part, not the trunk
        rho = np.linalg.norm(top - np.array([cx, cy, cz]), axis=1)
        assert (rho <= r + 0.1).all()
        assert np.median(r - rho) == pytest.approx(depth * math.log(2), abs=0.1)  # exponential depths
    # other leaves each epoch
    from scipy.spatial import cKDTree

    d, _ = cKDTree(leaves[1]).query(leaves[0])
    assert np.median(d) > 0.05
    # some pulses pass the crown and reach the ground under it
    g = slope[0]["xyz"][slope[0]["oid"] == 1]
    under = np.hypot(g[:, 0] - cx, g[:, 1] - cy) < 0.6 * r
    assert 0 < under.sum() < 0.5 * 20.0 * math.pi * (0.6 * r) ** 2


def test_a_flight_and_its_variation_refuse_nonsense() -> None:
    with pytest.raises(SynthError, match="altitude"):
        Flight(heading_deg=0.0, altitude_m=-5.0, spacing_m=30.0)
    with pytest.raises(SynthError, match="variation"):
        epoch_flight("slope", 0, 0, variation=-1.0)
    with pytest.raises(SynthError, match="layout"):
        epoch_flight("moon", 0, 0)


def test_the_sloped_scene_changes_what_it_says() -> None:
    before, after = ({(p.key, p.signature) for p in m.slope_scene(e)} for e in (0, 1))
    changed = {k for k, _ in before ^ after}
    assert changed == {"car", "stockpile", "trench", "pole", "fence:2"}
    site = m.SiteModel(n_epochs=2, layout="slope")
    assert site.terrain_m == m.SLOPE_TERRAIN_M and site.fence_m == m.SLOPE_FENCE_M
    # a box standing on the slope has its base at the lowest ground under it
    car = next(p for p in m.slope_scene(0) if p.key == "car")
    (x, y, z0), size, _ = car.params
    corners = np.array([[x + a * size[0] / 2, y + b * size[1] / 2] for a in (-1, 1) for b in (-1, 1)])
    assert z0 == pytest.approx(terrain_height(corners[:, 0], corners[:, 1], m.SLOPE_GRADE, None).min())
    assert isinstance(car, Primitive)
