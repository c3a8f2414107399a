"""The ground views stand on: ground found from geometry when no class says it, a terrain grid where
the site is not a plane, and views over a hillside that keep their height above the ground below."""

from __future__ import annotations

import numpy as np
import pytest

from siteline.camera.pinhole import Camera
from siteline.errors import ViewsError
from siteline.records.params.views import ViewParams
from siteline.views.generate import NamedCamera, generate_views
from siteline.views.ground import GroundPlane, fit_ground_plane, model_ground
from siteline.views.groundfilter import morphological_ground
from siteline.views.sources import ArrayPointSource
from siteline.views.terrain import TerrainGrid, terrain_grid

HALF = 100.0  # the hillside spans +-100 m
FENCE = [(-80.0, -80.0), (80.0, -80.0), (80.0, 80.0), (-80.0, 80.0)]


def hillside_z(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Flat west of x = 0, a 20 % slope east of it (20 m of rise), and a 12 m pit 30 m across at (40, -30)
    with 45-degree walls."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    z = 0.2 * np.maximum(x, 0.0)
    r = np.hypot(x - 40.0, y + 30.0)
    return z - np.clip(15.0 + 12.0 - r, 0.0, 12.0)


def _hillside(density: float = 1.0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n = int((2 * HALF) ** 2 * density)
    xy = rng.uniform(-HALF, HALF, (n, 2))
    return np.c_[xy, hillside_z(xy[:, 0], xy[:, 1]) + rng.normal(0, 0.03, n)]


def _buildings(rng: np.random.Generator, ground_z) -> np.ndarray:  # noqa: ANN001
    """Ten box roofs 5-30 m across, 3-15 m above the ground below them, and some tree crowns."""
    parts = []
    for _ in range(10):
        cx, cy = rng.uniform(-70, 70, 2)
        w = rng.uniform(5, 30)
        h = rng.uniform(3, 15)
        m = int(w * w)
        xy = np.c_[rng.uniform(cx - w / 2, cx + w / 2, m), rng.uniform(cy - w / 2, cy + w / 2, m)]
        parts.append(np.c_[xy, ground_z(xy[:, 0], xy[:, 1]) + h])
    for _ in range(30):
        cx, cy = rng.uniform(-90, 90, 2)
        xy = rng.normal((cx, cy), 2.0, (40, 2))
        parts.append(np.c_[xy, ground_z(xy[:, 0], xy[:, 1]) + rng.uniform(4, 12, 40)])
    return np.concatenate(parts)


def test_the_morphological_filter_finds_the_ground_under_buildings_and_trees() -> None:
    rng = np.random.default_rng(1)
    ground = _hillside(1.0)
    above = _buildings(rng, hillside_z)
    xyz = np.concatenate([ground, above])
    found = morphological_ground(xyz)
    truth = np.r_[np.ones(len(ground), bool), np.zeros(len(above), bool)]
    assert (found & truth).sum() / found.sum() > 0.99  # no roof or crown taken for ground
    g = found[: len(ground)]
    pit = np.hypot(ground[:, 0] - 40.0, ground[:, 1] + 30.0) < 27.0
    assert g[(ground[:, 0] < 0) & ~pit].mean() > 0.99  # the flat half
    assert g[(ground[:, 0] > 0) & ~pit].mean() > 0.93  # the 20 % slope
    # the pit's 45-degree walls are steeper than the filter's slope: they are cut, its floor is kept
    floor = np.hypot(ground[:, 0] - 40.0, ground[:, 1] + 30.0) < 12.0
    assert g[floor].mean() > 0.95 and g[pit & ~floor].mean() < 0.9


def test_a_terrain_grid_interpolates_a_plane_exactly_and_meets_the_optical_axis() -> None:
    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 50, (20_000, 2))
    pts = np.c_[xy, 0.1 * xy[:, 0] - 0.05 * xy[:, 1] + 3.0]
    grid, held = terrain_grid(pts, cell_m=2.0)
    assert held.mean() > 0.99
    q = rng.uniform(5, 45, (100, 2))
    # a cell's mean of a plane is the plane at the points' mean: within a few centimetres
    assert np.abs(grid.z_at(q) - (0.1 * q[:, 0] - 0.05 * q[:, 1] + 3.0)).max() < 0.05
    C = np.array([25.0, 25.0, 60.0])
    f = np.array([0.3, 0.0, -1.0]) / np.hypot(0.3, 1.0)
    hit = grid.axis_hit(C, f)
    assert hit is not None and abs(grid.height(hit)) < 0.01
    # the analytic answer: 60 + t f_z = 0.1 (25 + t f_x) - 1.25 + 3
    t = (60.0 - 2.5 + 1.25 - 3.0) / (0.1 * f[0] - f[2])
    assert np.allclose(hit, C + t * f, atol=0.1)
    assert grid.axis_hit(C, np.array([0.0, 0.0, 1.0])) is None  # looking up meets nothing
    moved = grid.keep_height(C, np.array([5.0, 40.0, 60.0]))
    assert grid.height(moved) == pytest.approx(grid.height(C))


def test_a_flat_site_keeps_its_plane_and_a_hillside_gets_a_terrain() -> None:
    rng = np.random.default_rng(3)
    flat = np.c_[rng.uniform(-50, 50, (30_000, 2)), rng.normal(0, 0.03, 30_000)]
    choice = model_ground(flat, np.ones(len(flat), bool) & (rng.random(len(flat)) < 0.6))
    assert isinstance(choice.model, GroundPlane) and choice.source == "class" and choice.residual_m < 0.1
    hill = _hillside(1.0)
    choice = model_ground(hill, rng.random(len(hill)) < 0.6)
    assert isinstance(choice.model, TerrainGrid) and choice.kind == "terrain" and choice.residual_m > 1.0
    assert "terrain grid" not in choice.to_dict()  # a record, not prose
    assert choice.to_dict()["cell_m"] == choice.model.cell_m


def test_no_ground_class_gives_ground_from_geometry_and_none_at_all_is_refused() -> None:
    rng = np.random.default_rng(4)
    ground = _hillside(0.5)
    xyz = np.concatenate([ground, _buildings(rng, hillside_z)])
    for classes in (np.zeros(len(xyz), bool), np.ones(len(xyz), bool)):  # class 0 only; everything "ground"
        choice = model_ground(xyz, classes)
        assert choice.source == "morphology" and choice.filter is not None
        assert abs(choice.share - len(ground) / len(xyz)) < 0.06  # less the pit walls (above)
    with pytest.raises(ViewsError, match="ground points"):
        model_ground(np.zeros((2, 3)), np.zeros(2, bool))


def _hill_cameras() -> list[NamedCamera]:
    """Oblique survey cameras 40 m above the ground below them, over both halves of the hillside."""
    out = []
    for i, (x, y) in enumerate((x, y) for x in (-60.0, -30.0, 30.0, 60.0) for y in (-50.0, 0.0, 50.0)):
        z = float(hillside_z(x, y)) + 40.0
        target = (0.8 * x, 0.8 * y, float(hillside_z(0.8 * x, 0.8 * y)))
        out.append(NamedCamera(f"DJI_{i:04d}.JPG", Camera.look_at((x, y, z), target, 160, 120, fx=130.0)))
    return out


def _views(ground) -> list:  # noqa: ANN001
    xyz = _hillside(0.5).astype(np.float32)
    params = ViewParams(views=400, min_coverage=0.2, clearance_m=0.5)
    return generate_views(_hill_cameras(), ground, FENCE, ArrayPointSource(xyz), params).views


def test_views_over_a_hillside_keep_their_height_above_the_terrain_below() -> None:
    pts = _hillside(0.5)
    choice = model_ground(pts, np.ones(len(pts), bool))
    assert choice.kind == "terrain"
    views = _views(choice.model)
    parents = {c.name: c.camera for c in _hill_cameras()}
    assert len(views) > 40
    checked = 0
    for v in views:
        C = v.camera.center
        height = C[2] - float(hillside_z(C[0], C[1]))
        assert height >= 0.9, (v.strategy, height)  # none under the ground (1 m minimum, 10 cm of grid)
        if v.params.forward_fraction == 0:
            P = parents[v.parent].center
            planned = v.params.vertical_fraction * (P[2] - float(hillside_z(P[0], P[1])))
            assert abs(height - planned) <= 0.1 * planned, (v.strategy, height, planned)
            checked += 1
    assert checked > 10


def test_before_the_terrain_one_plane_put_views_under_the_hillside() -> None:
    pts = _hillside(0.5)
    views = _views(fit_ground_plane(pts, seed=0))  # what views were placed against until now
    heights = np.array([v.camera.center[2] - float(hillside_z(*v.camera.center[:2])) for v in views])
    assert (heights < 0).sum() >= 1, heights.min()  # 3 views under the ground, one 10 m under, when written
