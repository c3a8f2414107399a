"""3D change labels: brute-force equality, agreement with the synthetic truth, origin invariance."""

from __future__ import annotations

import json

import laspy
import numpy as np
import pytest
from scipy.spatial import cKDTree
from sitehelpers import SYNTH, epoch_dirs

from siteline.labels.change import CHANGED, IGNORED, UNCHANGED, Matching, change_flags
from siteline.labels.regions import RegionRule
from siteline.labels.store import write_labels
from siteline.pointpass import TilingResources
from siteline.site.taxonomy import default_taxonomy
from siteline.synth import LAS_RELPATH
from siteline.tiles.reader import SceneTiles
from siteline.tiles.writer import TileInput, write_tiles

TAX = default_taxonomy()
IGN = TAX.ignored_lut()


def _brute(a_xyz, a_cls, b_xyz, b_cls, r):
    """Reference: for each point, scan every point of B (no tree, no tiles)."""
    out = np.full(len(a_xyz), IGNORED, np.uint8)
    keep = ~IGN[b_cls]
    for i in range(len(a_xyz)):
        if IGN[a_cls[i]]:
            continue
        d = np.linalg.norm(b_xyz[keep] - a_xyz[i], axis=1)
        if d.size == 0 or d.min() > r:
            out[i] = CHANGED
        else:
            out[i] = UNCHANGED if b_cls[keep][d.argmin()] == a_cls[i] else CHANGED
    return out


def test_change_flags_equal_brute_force_on_small_scenes() -> None:
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 5, (600, 3))
    b = np.concatenate([a[:400] + rng.normal(0, 0.01, (400, 3)), rng.uniform(0, 5, (100, 3))])
    ac = rng.choice(np.array([1, 2, 3, 10], np.uint8), 600)
    bc = np.concatenate([ac[:400], rng.choice(np.array([1, 2, 255], np.uint8), 100)])
    bc[:50] = 4  # the same place, another class
    for r in (0.05, 0.3):
        for backend in ("pykdtree", "ckdtree"):
            assert np.array_equal(
                change_flags(a, ac, b, bc, r, IGN, Matching(backend)), _brute(a, ac, b, bc, r)
            )


def test_edge_cases() -> None:
    a = np.zeros((3, 3))
    cls = np.array([1, 10, 2], np.uint8)  # ground, snow (ignored), building
    assert change_flags(a, cls, np.zeros((0, 3)), np.zeros(0, np.uint8), 0.5, IGN).tolist() == [
        CHANGED,
        IGNORED,
        CHANGED,
    ]
    only_ignored = np.array([255, 9], np.uint8)
    assert change_flags(a, cls, np.zeros((2, 3)), only_ignored, 0.5, IGN).tolist() == [
        CHANGED,
        IGNORED,
        CHANGED,
    ]


def _site_tiles(tmp_path, synth_site, index, origin=SYNTH.origin, name="s"):
    import pyproj

    from siteline.site.fence import load_fence_geojson
    from siteline.site.spec import make_site_spec

    ring = load_fence_geojson(synth_site / "fence.geojson", SYNTH.origin)
    site = make_site_spec("s", SYNTH.crs, origin, [*ring, ring[0]])
    las = epoch_dirs(synth_site)[index] / LAS_RELPATH
    r = write_tiles(
        TileInput(las, site, pyproj.CRS(SYNTH.crs)),
        tmp_path / f"{name}{index}.zarr",
        resources=TilingResources(workers=1),
    )
    return SceneTiles.open(r.uri)


@pytest.mark.parametrize("rule", ["nearest", "adaptive"])
def test_tiled_labels_equal_whole_cloud_labels(tmp_path, synth_site, rule) -> None:
    """Each tile against the other scene's halo gives the flags of the whole clouds: the nearest
    rule, and the adaptive rule, whose fit and plan cells reach farther (its halo, SurfaceTest.halo_m)."""
    from siteline.labels.change import Matching
    from siteline.records.params.labels import LabelParams

    t1, t2 = _site_tiles(tmp_path, synth_site, 0), _site_tiles(tmp_path, synth_site, 1)
    r = 0.5
    test = LabelParams(rule=rule, surface_probe=0.7).surface_test(r)
    matching = Matching(surface=test, ground=TAX.ground_lut() if test is not None else None)
    res = write_labels(t1, t2, r, IGN, tmp_path / "labels.zarr", matching=matching)
    for tiles, other, side in ((t1, t2, "t1"), (t2, t1, "t2")):
        labelled = tiles.with_attribute("change", str(tmp_path / "labels.zarr" / side))
        mine = labelled.points(attributes=("class", "change"))
        theirs = other.points(attributes=("class",))
        a, b = mine.xyz_m.astype(np.float32), theirs.xyz_m.astype(np.float32)  # as points() gave them before
        whole = change_flags(a, mine.attributes["class"], b, theirs.attributes["class"], r, IGN, matching)
        assert np.array_equal(mine.attributes["change"], whole)
    assert res.counts["t1"]["changed"] > 0 and res.counts["t2"]["unchanged"] > 0


def _truth(site, index, key):
    name = epoch_dirs(site)[index].name
    return np.load(site / "truth" / name / f"{key}.npy")


def _local(site, index):
    """Site-local points and site classes as ingest makes them (taxonomy, outside the fence -> ignore)."""
    from siteline.site.fence import inside_fence, load_fence_geojson

    las = laspy.read(epoch_dirs(site)[index] / LAS_RELPATH)
    xyz = np.c_[las.x, las.y, las.z] - np.asarray(SYNTH.origin)
    lut, _ = TAX.code_lut("las")
    cls = lut[np.asarray(las.classification)]
    fence = load_fence_geojson(site / "fence.geojson", SYNTH.origin)
    return xyz, np.where(inside_fence(xyz[:, :2], fence), cls, TAX.ignore_id).astype(np.uint8)


def _near_fence(xy, site, distance_m=1.0):
    import shapely

    from siteline.site.fence import load_fence_geojson

    ring = shapely.LinearRing(load_fence_geojson(site / "fence.geojson", SYNTH.origin))
    return shapely.distance(ring, shapely.points(xy)) < distance_m


@pytest.mark.parametrize("pair", [(0, 1), (1, 2)])
def test_labels_agree_with_synthetic_truth(synth_site, pair) -> None:
    i, j = pair
    xa, ca = _local(synth_site, i)
    xb, cb = _local(synth_site, j)
    spacing = max(cKDTree(x).query(x[:20000], k=2)[0][:, 1].mean() for x in (xa, xb))
    r = 2.5 * spacing
    ta, tb = _truth(synth_site, i, "changed_until_next"), _truth(synth_site, j, "changed_since_previous")
    ma, mb = _truth(synth_site, i, "margin_next_m"), _truth(synth_site, j, "margin_previous_m")
    for x, c, t_mine, m_mine, xo, co, t_other in ((xa, ca, ta, ma, xb, cb, tb), (xb, cb, tb, mb, xa, ca, ta)):
        flags = change_flags(x, c, xo, co, r, IGN)
        live = flags != IGNORED
        # object boundaries: within 1 m (horizontally) of a truly changed point of either scene
        changed_xy = np.concatenate([x[t_mine][:, :2], xo[t_other][:, :2]])
        near = cKDTree(changed_xy).query(x[:, :2], distance_upper_bound=1.0)[0] < np.inf
        near |= _near_fence(x[:, :2], synth_site)  # the fence line is an object boundary too
        unchanged = live & ~t_mine & ~near
        assert (flags[unchanged] == UNCHANGED).mean() >= 0.99
        # changes that moved a surface by more than the radius (smaller ones are below the method's
        # resolution: the truth's margin says by how much each changed point moved)
        detectable = live & t_mine & (m_mine > r)
        # ... and not within r of an unchanged surface of the other scene (a new wall against a kept
        # column: the rule's stated blind spot, siteline.labels.change)
        kept = cKDTree(xo[~t_other])
        detectable &= ~(kept.query(x, distance_upper_bound=r)[0] < np.inf)
        assert detectable.sum() > 100
        assert (flags[detectable] == CHANGED).mean() >= 0.98


def test_labels_identical_at_origin_and_georeferenced(tmp_path) -> None:
    from siteline.synth import SynthParams, write_site

    outs = []
    for k, origin in enumerate([(0.0, 0.0, 0.0), (445_000.0, 5_030_000.0, 80.0)]):
        d = tmp_path / f"s{k}"
        write_site(
            d, SynthParams(epochs=2, density_pts_m2=1.5, seed=9, origin=origin, photos=False, colmap=False)
        )
        xa = laspy.read(epoch_dirs(d)[0] / LAS_RELPATH)
        xb = laspy.read(epoch_dirs(d)[1] / LAS_RELPATH)
        la = np.c_[xa.x, xa.y, xa.z] - np.asarray(origin)
        lb = np.c_[xb.x, xb.y, xb.z] - np.asarray(origin)
        lut, _ = TAX.code_lut("las")
        outs.append(
            change_flags(
                la.astype(np.float32),
                lut[np.asarray(xa.classification)],
                lb.astype(np.float32),
                lut[np.asarray(xb.classification)],
                0.8,
                IGN,
            )
        )
    assert np.array_equal(outs[0], outs[1])


def test_truth_sidecar_is_json_describable(synth_site) -> None:
    doc = json.loads((synth_site / "truth" / "site.json").read_text())
    assert len(doc["epochs"]) == SYNTH.epochs


def test_labelling_holds_a_few_whole_tiles_whatever_the_site(tmp_path, synth_site) -> None:
    """Column by column, at most two whole tiles a scene are held (the one labelled and the next of its
    column), the rest as strips of the columns still needed; each tile is decoded at most twice, and a
    halo equals the points of the widened cell taken from the whole scene."""
    from siteline.labels.store import _STRIP_MARGIN_M, _WHOLE_TILES, _Decoded, _join

    tiles = _site_tiles(tmp_path, synth_site, 0)
    r = 0.5
    dec = _Decoded(tiles, r)
    everything = tiles.points(attributes=("class",))
    grid = sorted(dec.keys)
    assert len({i for i, _ in grid}) > 2 and len({j for _, j in grid}) > 1  # columns and rows to hold
    size = tiles.spec.tile_size_m
    for ij in grid:
        dec.release_before(ij[0])
        xyz, _ = _join(dec.halo(ij))
        assert len(dec._whole) <= _WHOLE_TILES
        assert all(i >= ij[0] - 1 for i, _ in dec._strips)
        x0, y0 = ij[0] * size, ij[1] * size
        p, r = everything.xyz_m, 0.5 + _STRIP_MARGIN_M
        inside = (
            (p[:, 0] >= x0 - r)
            & (p[:, 0] <= x0 + size + r)
            & (p[:, 1] >= y0 - r)
            & (p[:, 1] <= y0 + size + r)
        )
        # the strips take a neighbour's points within r of the shared edge: the widened cell, up to
        # points on the cell's own border lines that belong to the next tile
        assert abs(len(xyz) - int(inside.sum())) <= max(10, int(0.001 * inside.sum()))
    assert dec.decodes <= 2 * len(grid)


def test_labels_in_slabs_equal_labels_of_whole_tiles(tmp_path, synth_site, monkeypatch) -> None:
    """A tile labelled in slabs of a few thousand points (each against the other scene within the halo)
    gives the flags of the whole tile, with the surface rule and small regions, and with the adaptive
    rule (whose fit reaches 8 radii and plan cells two cells' width): the same checksum."""
    from siteline.labels import store
    from siteline.labels.change import Matching
    from siteline.records.params.labels import LabelParams

    t1, t2 = _site_tiles(tmp_path, synth_site, 0), _site_tiles(tmp_path, synth_site, 1)
    r = 0.5
    for name in ("surface", "adaptive"):
        test = LabelParams(rule=name, surface_probe=0.7).surface_test(r)
        rule = {
            "matching": Matching(surface=test, ground=TAX.ground_lut()),
            "regions": RegionRule(3, sparse=True),
        }
        monkeypatch.setattr(store, "BLOCK_POINTS", 2_000_000)
        whole = write_labels(t1, t2, r, IGN, tmp_path / f"{name}-whole.zarr", **rule)
        monkeypatch.setattr(store, "BLOCK_POINTS", 1_000)
        slabs = write_labels(t1, t2, r, IGN, tmp_path / f"{name}-slabs.zarr", **rule)
        assert max(t.prefix(k) for t in (t1, t2) for k in t.by_tile) > 1_000 * 5  # tiles of several slabs
        assert slabs.checksum == whole.checksum and slabs.counts == whole.counts, name


def test_slabs_take_every_point_once_in_bounded_runs_along_x() -> None:
    from siteline.labels.store import _slab_cuts, _slabs

    def slabs_of(x: np.ndarray, size: int) -> list[np.ndarray]:
        return [idx for _, idx in _slabs(x, _slab_cuts(x, size))]

    rng = np.random.default_rng(2)
    x = np.concatenate([rng.uniform(0, 100, 50_000), np.full(3_000, 42.0)]).astype(np.float32)  # a wall
    slabs = slabs_of(x, 5_000)
    taken = np.concatenate(slabs)
    assert np.array_equal(np.sort(taken), np.arange(len(x)))
    assert len(slabs) >= 10 and max(len(s) for s in slabs) <= 5_000 + 3_000 + 700
    assert all(x[a].max() <= x[b].min() for a, b in zip(slabs[:-1], slabs[1:], strict=True))
    assert [len(s) for s in slabs_of(np.full(10, 3.0, np.float32), 4)] == [
        10
    ]  # one value: one slab, none empty


def _array_tiles(tmp_path, xyz: np.ndarray, name: str) -> SceneTiles:
    """A scene tiled from site-local points (all ground class but the first ``poles`` points)."""
    import pyproj

    from siteline.site.spec import make_site_spec

    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array(SYNTH.origin)
    las = laspy.LasData(header)
    world = xyz + np.array(SYNTH.origin)
    las.x, las.y, las.z = world[:, 0], world[:, 1], world[:, 2]
    las.classification = np.where(xyz[:, 2] > 0.5, 26, 2).astype(np.uint8)  # temporary works, ground
    path = tmp_path / f"{name}.las"
    las.write(path)
    site = make_site_spec("s", SYNTH.crs, SYNTH.origin)
    r = write_tiles(
        TileInput(path, site, pyproj.CRS(SYNTH.crs)),
        tmp_path / f"{name}.zarr",
        resources=TilingResources(workers=1),
    )
    return SceneTiles.open(r.uri)


def test_a_sparse_poles_samples_are_each_kept_as_a_change(tmp_path) -> None:
    """A pole put up between two scans, sampled a metre apart on its sides (a flight's airborne
    scan: the sloped scene's pole had 24 points over 6 m): each sample is farther from the next than
    the region cells link, yet none is taken back to unchanged as a region too small; a lone stray
    point on the ground plane is."""
    rng = np.random.default_rng(5)

    def ground(n: int) -> np.ndarray:
        return np.c_[rng.uniform(0, 20, (n, 2)), rng.normal(0, 0.01, n)]

    pole = np.c_[np.full(7, 10.0), np.full(7, 10.0), np.arange(1.0, 8.0) + rng.uniform(-0.1, 0.1, 7)]
    stray = np.array([[3.0, 3.0, 0.35]])  # one point a little off the ground: an isolated flag
    t1 = _array_tiles(tmp_path, ground(32000), "before")
    t2 = _array_tiles(tmp_path, np.concatenate([ground(32000), pole, stray]), "after")
    res = write_labels(t1, t2, 0.2, IGN, tmp_path / "labels.zarr", regions=RegionRule(3, sparse=True))
    labelled = t2.with_attribute("change", str(tmp_path / "labels.zarr" / "t2")).points(
        attributes=("change",)
    )
    xyz, change = labelled.xyz_m, labelled.attributes["change"]
    on_pole = np.hypot(xyz[:, 0] - 10.0, xyz[:, 1] - 10.0) < 0.01
    assert on_pole.sum() == 7 and (change[on_pole] == CHANGED).all()
    at_stray = np.linalg.norm(xyz - stray[0], axis=1) < 0.01
    assert (change[at_stray] == UNCHANGED).all() and res.counts["t2"]["changed"] == 7
    # without the knob (the labels of before) every sample of the pole is a region too small
    before = write_labels(t1, t2, 0.2, IGN, tmp_path / "labels-before.zarr", regions=RegionRule(3))
    assert before.counts["t2"]["changed"] == 0


def test_chance_flags_on_a_wall_sparser_than_the_ground_are_not_kept_whole() -> None:
    """A wall sampled 0.25 m apart over ground 0.1 m apart is sparse against its tile, but its samples
    lie within the 0.4 m region cells of each other: a few of them flagged a metre apart look sparse
    among the changed points alone, yet not among the wall's own; none is kept whole (and nothing
    fails where no sparse point is left to vote)."""
    from siteline.labels.store import _sparse

    g = np.arange(0.0, 8.0, 0.1)
    gx, gy = np.meshgrid(g, g)
    ground = np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]
    w = np.arange(0.0, 8.0, 0.25)
    wy, wz = np.meshgrid(w, np.arange(0.5, 3.0, 0.25))
    wall = np.c_[np.full(wy.size, 4.0), wy.ravel(), wz.ravel()]
    xyz = np.concatenate([ground, wall])
    changed = np.zeros(len(xyz), bool)
    changed[len(ground) :: 13] = True  # every 13th wall sample, about a metre apart
    kept = _sparse(xyz, changed, 0.1, 0.4)
    assert kept is None or not kept.any()
