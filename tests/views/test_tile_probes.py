"""View generation on a tiled scene: a scene that fits in memory is read once and every probe judged
from there; a larger one is read per probe (frustum-culled tiles at the probe's own level of detail),
never whole; both keep what the whole-cloud probes kept."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from siteline.catalog.scenes import scene_cameras, tile_source
from siteline.catalog.sites import site_of
from siteline.pairs.sources import TilePointSource
from siteline.records.pairs import ViewStrategy
from siteline.records.params.views import ViewParams
from siteline.tiles.reader import SceneTiles
from siteline.views.generate import NamedCamera, generate_views
from siteline.views.ground import fit_ground_plane
from siteline.views.sources import ProbePoints

PARAMS = ViewParams(scale=0.25, views=12, min_coverage=0.3)
SKIP = np.array([9, 10], np.uint8)


def _inputs(cat):  # noqa: ANN001, ANN202
    with cat.transaction() as s:
        tiles = SceneTiles.from_source(tile_source(s, 2))
        cams = [NamedCamera(n, c) for n, c in scene_cameras(s, 2)[:8]]
        site = site_of(s, 1)
    g = tiles.points(resolution=0.5, attributes=("class",))
    on_ground = g.attributes["class"] == site.taxonomy.id_of("ground")
    plane = fit_ground_plane(g.xyz_m[on_ground].astype(np.float32), seed=0)
    return tiles, cams, site, plane


class WholeCloud(TilePointSource):
    """The previous source: every probe rendered the whole scene read once at 5 cm."""

    def __init__(self, tiles: SceneTiles, skip: np.ndarray) -> None:
        super().__init__(tiles, skip)
        probe = tiles.points(resolution=0.05, attributes=("class",))
        self._probe = probe.xyz_m[~np.isin(probe.attributes["class"], skip)].astype(np.float32)

    def points_for_view(self, camera, scale):  # noqa: ANN001, ANN201
        return ProbePoints(self._probe)


def test_probes_of_a_large_scene_read_culled_tiles_only(scenes, monkeypatch) -> None:
    _, cat = scenes
    tiles, cams, site, plane = _inputs(cat)
    source = TilePointSource(tiles, SKIP, memory_points=0)  # as a scene larger than memory is
    assert not source.in_memory
    read_at_start = source.points_read

    def whole_scene_read(*a, **k):  # noqa: ANN002, ANN003, ANN202
        raise AssertionError("view generation read the scene without a frustum")

    monkeypatch.setattr(SceneTiles, "points", whole_scene_read)
    view_set = generate_views(cams, plane, site.fence, source, PARAMS)
    assert view_set.views and source.reads > 2
    # each read took a fraction of the scene: the frustum's tiles at the probes' level of detail
    assert (source.points_read - read_at_start) / (source.reads - 1) < 0.5 * tiles.point_count


def test_a_scene_that_fits_in_memory_is_read_once(scenes, monkeypatch) -> None:
    _, cat = scenes
    tiles, cams, site, plane = _inputs(cat)
    source = TilePointSource(tiles, SKIP)
    assert source.in_memory and source.reads == 1 and source.points_read == tiles.point_count
    monkeypatch.setattr(SceneTiles, "read_nodes", lambda *a, **k: pytest.fail("a probe read the store"))
    view_set = generate_views(cams, plane, site.fence, source, PARAMS)
    assert view_set.views and source.reads == 1 and source.points_read == tiles.point_count
    assert source.probes >= view_set.probed


def test_tiled_probes_keep_the_whole_cloud_views(scenes) -> None:
    """The level of detail changes a probe's coverage by a few pixels: the same views pass, up to a
    view whose coverage lies that close to ``min_coverage`` (none here)."""
    _, cat = scenes
    tiles, cams, site, plane = _inputs(cat)
    new = generate_views(cams, plane, site.fence, TilePointSource(tiles, SKIP), PARAMS)
    old = generate_views(cams, plane, site.fence, WholeCloud(tiles, SKIP), PARAMS)
    assert [(v.parent, v.strategy) for v in new.views] == [(v.parent, v.strategy) for v in old.views]
    cov_new = np.array([v.coverage for v in new.views])
    cov_old = np.array([v.coverage for v in old.views])
    assert np.abs(cov_new - cov_old).max() < 0.05


@pytest.mark.parametrize("n", [1, 5, 40])
def test_stratified_order_prefixes_are_the_samples(n) -> None:
    from siteline.views.generate import SyntheticView, key_sorted, stratified_order, stratified_sample

    views = [
        SyntheticView(f"img{i % 7}", f"s{i % 3}", ViewStrategy(1.0, False, 0.0), None) for i in range(30)
    ]  # no geometry needed
    order = stratified_order(views, seed=3)
    assert len(order) == 30 and len({id(v) for v in order}) == 30
    assert stratified_sample(views, n, seed=3) == key_sorted(order[:n], seed=3)


def test_a_prefetched_batch_serves_each_probe_the_points_of_its_own_read(scenes) -> None:
    """A parent camera's probes read together give each probe exactly the points (as a set) that its
    own read gives, and read fewer points in all than one read per probe."""
    _, cat = scenes
    tiles, cams, _, _ = _inputs(cat)
    probes = [c.camera for c in cams[:6]]
    single, batched = (
        TilePointSource(tiles, SKIP, memory_points=0),
        TilePointSource(tiles, SKIP, memory_points=0),
    )
    held = TilePointSource(tiles, SKIP, whole_points=0)  # node prefixes from memory
    before = (single.reads, single.points_read, batched.points_read)
    own = [single.points_for_view(c, PARAMS.scale) for c in probes]
    batched.prefetch(probes, PARAMS.scale)
    got = [batched.points_for_view(c, PARAMS.scale) for c in probes]
    from_memory = [held.points_for_view(c, PARAMS.scale) for c in probes]

    def rows(p: ProbePoints) -> np.ndarray:  # a probe's points with their spacing and kept flag, as a set
        return np.unique(np.c_[p.xyz, p.spacing_m, p.kept], axis=0)

    for mine, theirs, memory in zip(own, got, from_memory, strict=True):
        assert len(mine.xyz) and np.array_equal(rows(mine), rows(theirs))
        assert np.array_equal(rows(mine), rows(memory))
    assert batched.reads == before[0] + 1
    assert batched.points_read - before[2] < single.points_read - before[1]


def test_coverage_of_equals_the_renders_coverage() -> None:
    from siteline.camera.pinhole import Camera
    from siteline.records.params.render import RenderParams
    from siteline.render.zbuffer import coverage_of, render_points

    rng = np.random.default_rng(0)
    for k in range(60):
        xyz = rng.normal(0, 10, (int(rng.integers(0, 3000)), 3)).astype(np.float32)
        if len(xyz) and k % 5 == 0:
            xyz[0] = np.nan
        w, h = (int(v) for v in rng.integers(20, 160, 2))
        cam = Camera.look_at(rng.normal(0, 5, 3) + [0, 0, 40], [0, 0, 0], w, h, float(rng.uniform(20, 200)))
        s = RenderParams(
            scale=float(rng.choice([0.37, 0.5, 1.0])), point_size_px=int(rng.choice([1, 3, 5, 7]))
        )
        assert coverage_of(xyz, cam, s).hit == render_points(xyz, cam, s).coverage


def test_clearance_is_measured_on_both_scenes_at_full_density(scenes) -> None:
    """A camera's distance to the nearest point is exact (the brute force over both scenes' every
    point), read only near the camera, in memory or from the store; the coarse copy it replaced
    misses points, and the earlier scene's points count (a camera inside what was removed)."""
    _, cat = scenes
    tiles, _, _, _ = _inputs(cat)
    with cat.transaction() as s:
        earlier = SceneTiles.from_source(tile_source(s, 1))
    solid = []
    for scene in (tiles, earlier):
        p = scene.points(attributes=("class",))
        solid.append(p.xyz_m[~np.isin(p.attributes["class"], SKIP)])
    rng = np.random.default_rng(3)
    near_points = np.concatenate([a[rng.choice(len(a), 300, replace=False)] for a in solid])
    step = rng.normal(size=near_points.shape)
    q = near_points + step / np.linalg.norm(step, axis=1, keepdims=True) * rng.uniform(
        0.2, 4.0, (len(step), 1)
    )
    truth_both = cKDTree(np.concatenate(solid)).query(q)[0]
    truth_later = cKDTree(solid[0]).query(q)[0]
    for source in (
        TilePointSource(tiles, SKIP, others=(earlier,)),
        TilePointSource(tiles, SKIP, others=(earlier,), memory_points=0),
    ):
        got = source.nearest_within(q, 3.0)
        within = truth_both < 3.0
        assert within.sum() > 100 and (~within).sum() > 10
        np.testing.assert_allclose(got[within], truth_both[within], atol=1e-4)
        assert np.all(np.isinf(got[~within]))
    # the earlier scene's points alone hold some cameras back (a removed object's place)
    alone = TilePointSource(tiles, SKIP).nearest_within(q, 3.0)
    assert np.sum(np.isinf(alone) & (truth_both < 3.0)) > 0
    assert np.all(np.isinf(alone[truth_later >= 3.0]))
    # the coarse copy finds the nearest point farther than it is (a few here: this scene is sparse)
    coarse = source._coarse.nearest_within(q, 10.0)
    assert np.sum(coarse > truth_later + 0.05) > 0
    # a camera high above the site reads nothing
    reads = source.reads
    assert np.isinf(source.nearest_within(np.array([[0.0, 0.0, 500.0]]), 3.0)[0]) and source.reads == reads
