"""The surface rule and the region filter: unchanged surfaces sampled at random do not speckle, real
changes (a box removed, a thin beam moved, a slab lowered) are found, scan shadows are not change."""

from __future__ import annotations

import math

import numpy as np
import pytest

from siteline.labels.change import (
    CHANGED,
    IGNORED,
    UNCHANGED,
    Matching,
    change_flags,
    hidden_from_other,
    median_spacing,
)
from siteline.labels.regions import RegionCells, region_sizes, small_regions
from siteline.records.params.labels import LabelParams, SurfaceTest
from siteline.site.taxonomy import default_taxonomy

TAX = default_taxonomy()
IGN = TAX.ignored_lut()
GROUND = TAX.id_of("ground")
CRANE = TAX.id_of("crane")


def plane(
    rng: np.random.Generator, n: int, size: float = 20.0, z: float = 0.0, noise: float = 0.02
) -> np.ndarray:
    xy = rng.uniform(0, size, (n, 2))
    return np.c_[xy, z + rng.normal(0, noise, n)]


def beam(rng: np.random.Generator, n: int, x0: float, y0: float, length: float, z: float) -> np.ndarray:
    """The top of a 0.5 m wide beam along x."""
    return np.c_[rng.uniform(x0, x0 + length, n), rng.uniform(y0, y0 + 0.5, n), np.full(n, z)]


def flags(
    a: np.ndarray, ac: np.ndarray, b: np.ndarray, bc: np.ndarray, r: float, surface: bool
) -> np.ndarray:
    test = SurfaceTest(search_m=2 * r) if surface else None
    return change_flags(a, ac, b, bc, r, IGN, Matching(surface=test))


def test_unchanged_random_surfaces_speckle_under_the_nearest_rule_and_not_under_the_surface_rule():
    rng = np.random.default_rng(0)
    a, b = plane(rng, 40_000), plane(rng, 40_000)  # 100 points/m2, two independent samplings
    cls = np.full(len(a), GROUND, np.uint8)
    r = 2.5 * max(median_spacing(a), median_spacing(b))
    nearest = flags(a, cls, b, cls, r, surface=False)
    surface = flags(a, cls, b, cls, r, surface=True)
    # about 2^-k^2 at k = 2.5 (less here: the range noise widens the measured spacing)
    assert 0.002 < (nearest == CHANGED).mean() < 0.03
    assert (surface == CHANGED).mean() < (nearest == CHANGED).mean() / 20


def test_the_surface_rule_finds_a_removed_box_a_moved_beam_and_a_lowered_slab():
    rng = np.random.default_rng(1)
    ground_a, ground_b = plane(rng, 20_000), plane(rng, 20_000)
    box_top = np.c_[rng.uniform(5, 8, 900), rng.uniform(5, 8, 900), np.full(900, 2.5)]  # removed
    beam_a, beam_b = beam(rng, 1000, 2, 14, 10, 6.0), beam(rng, 1000, 2, 16, 10, 6.0)  # moved 2 m
    slab_a = np.c_[rng.uniform(12, 18, 3600), rng.uniform(2, 8, 3600), np.full(3600, 1.0)]
    slab_b = np.c_[rng.uniform(12, 18, 3600), rng.uniform(2, 8, 3600), np.full(3600, 0.7)]  # 30 cm lower
    a = np.concatenate([ground_a, box_top, beam_a, slab_a])
    b = np.concatenate([ground_b, beam_b, slab_b])
    ac, bc = np.full(len(a), GROUND, np.uint8), np.full(len(b), GROUND, np.uint8)
    ac[len(ground_a) + 900 : len(ground_a) + 1900] = CRANE
    bc[len(ground_b) : len(ground_b) + 1000] = CRANE
    r = 0.25
    fa = flags(a, ac, b, bc, r, surface=True)
    n0 = len(ground_a)
    assert (fa[n0 : n0 + 900] == CHANGED).mean() > 0.99  # the box's top: nothing there in B
    assert (fa[n0 + 900 : n0 + 1900] == CHANGED).mean() > 0.99  # the beam moved away
    assert (fa[n0 + 1900 :] == CHANGED).mean() > 0.99  # the slab is 0.3 m off B's slab
    # ground far from every change stays unchanged
    far = (ground_a[:, 0] > 1) & (ground_a[:, 0] < 4) & (ground_a[:, 1] < 12)
    assert (fa[:n0][far] == UNCHANGED).all()


def test_a_point_the_other_scan_could_not_see_is_not_change():
    # B's ground under A's beam: A scanned the beam above it, not the ground
    rng = np.random.default_rng(2)
    under = np.c_[rng.uniform(5, 6, 200), rng.uniform(5, 6, 200), np.zeros(200)]
    a_beam = np.c_[rng.uniform(4, 7, 2000), rng.uniform(4, 7, 2000), np.full(2000, 10.0)]
    test = SurfaceTest(search_m=0.5)
    cells = hidden_from_other(a_beam, under, test)
    assert cells.covered.all() and cells.hidden.all()
    # the same points with A's ground under them as well: A saw through, they are not hidden
    a_ground = np.c_[rng.uniform(4, 7, 2000), rng.uniform(4, 7, 2000), np.full(2000, -3.0)]
    cells = hidden_from_other(np.concatenate([a_beam, a_ground]), under, test)
    assert cells.covered.all() and not cells.hidden.any()
    b_flags = flags(
        under, np.full(200, GROUND, np.uint8), a_beam, np.full(2000, CRANE, np.uint8), 0.2, surface=True
    )
    assert (b_flags == UNCHANGED).all()
    assert (
        flags(under, np.full(200, GROUND, np.uint8), a_beam, np.full(2000, CRANE, np.uint8), 0.2, False)
        == CHANGED
    ).all()


def test_regions_link_touching_cells_and_count_points():
    rng = np.random.default_rng(3)
    patch = np.c_[rng.uniform(0, 2, 400), rng.uniform(0, 2, 400), np.zeros(400)]
    singles = np.array([[10.0, 10.0, 0.0], [20.0, 0.0, 0.0], [20.3, 0.0, 0.0]])
    sizes = region_sizes(np.concatenate([patch, singles]), 0.25)
    assert (sizes[:400] == 400).all()
    assert sizes[400:].tolist() == [1, 2, 2]  # the last two touch (0.3 m apart, cells of 0.25 m)
    small = small_regions(np.concatenate([patch, singles]), 0.25, 3)
    assert small.tolist() == [False] * 400 + [True, True, True]
    assert not small_regions(singles, 0.25, 1).any()
    assert region_sizes(np.zeros((0, 3)), 0.25).tolist() == []


def test_region_cells_gathered_by_parts_equal_the_regions_of_all_points():
    """Changed points handed over tile by tile as cells (4 bytes a point) give the small regions of all
    the points at once, a region that crosses the parts' border counted whole."""
    rng = np.random.default_rng(5)
    pts = np.c_[rng.uniform(0, 20, 30_000), rng.uniform(0, 20, 30_000), rng.uniform(0, 3, 30_000)]
    pts = np.concatenate([pts[rng.random(len(pts)) < 0.02], [[9.99, 5.0, 1.0], [10.01, 5.0, 1.0]]])
    parts = [pts[pts[:, 0] < 10], pts[pts[:, 0] >= 10], np.zeros((0, 3))]
    cells = RegionCells(0.4)
    for part in parts:
        cells.add(part.astype(np.float32))
    expect = small_regions(np.concatenate(parts).astype(np.float32), 0.4, 4)
    got = cells.small(4)
    assert [len(g) for g in got] == [len(p) for p in parts]
    assert np.array_equal(np.concatenate(got), expect) and 0 < expect.sum() < len(expect)
    assert not np.concatenate(cells.small(1)).any()


def test_ground_deepened_by_less_than_the_radius_is_found_by_the_probe_and_even_ground_stays():
    # 100 points/m2 of ground; in B a 4 m wide strip is dug down by 0.85 r (0.17 m at r = 0.2 m): most
    # of its points find A's ground within the radius, so the nearest test (and the surface rule behind
    # it) call them unchanged; their nearest lies beyond the probe (0.7 r), and probed against A's
    # surface they lie 0.17 m off it (its level of detection: 5 cm): changed. The ground beside is not.
    rng = np.random.default_rng(6)
    a, b = plane(rng, 40_000, noise=0.005), plane(rng, 40_000, noise=0.005)
    strip = (b[:, 0] > 8) & (b[:, 0] < 12)
    inner = strip & (b[:, 0] > 8.5) & (b[:, 0] < 11.5)  # away from the steps at the strip's edges
    away = (b[:, 0] < 7) | (b[:, 0] > 13)
    r = 0.2
    cls = np.full(len(a), GROUND, np.uint8)
    probe = Matching(surface=LabelParams(surface_probe=0.7).surface_test(r))
    b[strip, 2] -= 0.85 * r
    without = flags(b, cls, a, cls, r, surface=True)
    probed = change_flags(b, cls, a, cls, r, IGN, probe)
    assert (without[inner] == CHANGED).mean() < 0.2
    assert (probed[inner] == CHANGED).mean() > 0.95
    assert (probed[away] == CHANGED).mean() < 0.001
    # what it hardly sees: a change of half the radius, nearer than the probe, is found only at the few
    # points whose nearest neighbour happens to lie beyond it
    b[strip, 2] += 0.35 * r
    assert (change_flags(b, cls, a, cls, r, IGN, probe)[inner] == CHANGED).mean() < 0.1


def test_label_params_refuse_unknown_rules_and_regions():
    assert LabelParams(rule="surface").surface_test(0.3) == SurfaceTest(search_m=0.6)
    probe = LabelParams(rule="surface", surface_probe=0.7).surface_test(0.3)
    assert probe == SurfaceTest(search_m=0.6, probe_m=pytest.approx(0.21), offset_m=pytest.approx(0.075))
    assert LabelParams(rule="nearest", surface_probe=0.7).surface_test(0.3) is None
    # under the level of detection's floor (5 cm) a probed point could not lie off the surface by more
    assert LabelParams(rule="surface", surface_probe=0.7).surface_test(0.04) == SurfaceTest(search_m=0.08)
    # the adaptive rule (the default) reaches 8 radii for at least 6 points around the point, and
    # ignores what the other scan did not observe
    adaptive = LabelParams(surface_probe=0.7).surface_test(0.3)
    assert LabelParams().rule == "adaptive" and adaptive == SurfaceTest(
        search_m=0.6, probe_m=pytest.approx(0.21), offset_m=pytest.approx(0.075), reach_m=pytest.approx(2.4),
        min_fit=6, surround=1.0, gap=3.0, anchored=True, observed=True,
    )  # fmt: skip
    assert adaptive.fit_m == pytest.approx(2.4) and SurfaceTest(search_m=0.6).fit_m == 0.6
    # it probes only at a radius of two floors (10 cm) or more; the surface rule from one floor
    assert LabelParams(surface_probe=0.7).surface_test(0.08).probe_m == math.inf
    assert LabelParams(rule="surface", surface_probe=0.7).surface_test(0.08).probe_m == pytest.approx(0.056)
    assert LabelParams(surface_probe=0.7).surface_test(0.12).probe_m == pytest.approx(0.084)
    for bad in (1.0, -0.1, True, "0.7"):
        with pytest.raises(Exception, match="surface_probe"):
            LabelParams(surface_probe=bad)
    assert LabelParams(rule="nearest").surface_test(0.3) is None
    with pytest.raises(Exception, match="label rule"):
        LabelParams(rule="m3c2")
    with pytest.raises(Exception, match="min_region_points"):
        LabelParams(min_region_points=0)


def test_pair_knobs_of_the_rule_and_splats_are_checked_and_keyed():
    from siteline.errors import PairError
    from siteline.records.params.pairs import PairParams

    base = PairParams()
    assert (base.label_rule, base.min_region_points, base.splat_factor) == ("adaptive", 3, 2.0)
    with pytest.raises(PairError, match="label rule 'm3c2'"):
        PairParams.from_dict({"label_rule": "m3c2"})
    with pytest.raises(PairError, match="splat_factor"):
        PairParams(splat_factor=0.1)
    # the label knobs name other outputs; the splat factor at its default keeps the key of before
    assert PairParams(label_rule="nearest").digest() != base.digest()
    assert PairParams(splat_factor=1.5).digest() != base.digest()
    assert PairParams(splat_factor=1.5).render_settings().splat_factor == 1.5
    assert PairParams(splat_factor=1.5).view_params_spec().probe_settings().splat_factor == 1.5
    # the edge trim is on by default, a knob of the renders, and names other outputs
    assert base.trim_edges and base.render_settings().trim_edges
    assert PairParams(trim_edges=False).digest() != base.digest()
    assert PairParams.BEFORE["trim_edges"] is False
    # unsure edges are ignored by default, and name other outputs; off, the masks of before keep their key
    assert base.unsure_edges and PairParams.BEFORE["unsure_edges"] is False
    assert PairParams(unsure_edges=False).digest() != base.digest()
    # sparse surfaces are kept by default, name other outputs and other labels; off, those of before
    assert base.sparse_surfaces and PairParams.BEFORE["sparse_surfaces"] is False
    assert base.render_settings().sparse_surfaces and base.label_params().sparse_regions
    assert PairParams(sparse_surfaces=False).digest() != base.digest()
    assert (
        not PairParams(unsure_edges=False).render_settings().sparse_surfaces
    )  # the ignore needs unsure edges
    assert PairParams(unsure_edges=False).label_params().sparse_regions  # the labels do not
    # the probe is on by default and names other labels; without it (or with the nearest rule, which
    # has none) the key is the one of before the probe existed
    assert base.surface_probe == 0.7 and base.label_params().surface_probe == 0.7
    assert PairParams.BEFORE["surface_probe"] == 0.0
    no_probe = PairParams(surface_probe=0.0)
    assert no_probe.digest() != base.digest() and no_probe.digest() != PairParams(surface_probe=0.5).digest()
    # the surface rule's key and the nearest rule's as they were before the probe existed (siteline at
    # 5b710e2), and the surface rule with its probe as it was the default before the adaptive rule
    # (under the sampler of then: keyed-sha256-2 draws other views, so every key moved with it)
    before = {"label_rule": "surface", "min_region_points": 8}

    def key_then(params: PairParams) -> str:  # nor were unsure edges ignored then, nor sparse surfaces kept
        object.__setattr__(params, "sampler", "keyed-sha256-1")
        object.__setattr__(params, "unsure_edges", False)
        object.__setattr__(params, "sparse_surfaces", False)
        return params.digest()

    # the edge trim's second version (2026-11-30: a surface's own points within 5 spacings, lines kept)
    # draws other masks, so these keys moved with it: b089ba124b36, 1f8b3442bcd8 and c37dfb211d03 before
    assert key_then(PairParams(**before, surface_probe=0.0)) == "b9e33a569db7"
    assert key_then(PairParams(label_rule="nearest", min_region_points=8)) == "74fa2794a2dc"
    assert key_then(PairParams(**before)) == "79299a8c1991"  # the default at 5b710e2-dae2f5c
    assert PairParams(**before).digest() != "79299a8c1991"  # new views, a new key
    trim_then = PairParams(**before, trim_edges=False)
    assert key_then(trim_then) != "c37dfb211d03" and trim_then.digest() != PairParams(**before).digest()
    assert base.digest() not in {PairParams(**before).digest(), no_probe.digest()}
    with pytest.raises(PairError, match="surface_probe"):
        PairParams(surface_probe=1.5)
    with pytest.raises(PairError, match="trim_edges"):
        PairParams.from_dict({"trim_edges": "yes"})


def test_a_point_where_the_other_scene_has_nothing_at_all_is_ignored():
    # A scanned 10 m of ground, B only the first 5 m: beyond, nothing says whether it changed
    rng = np.random.default_rng(4)
    a = np.c_[rng.uniform(0, 10, 4000), rng.uniform(0, 4, 4000), np.zeros(4000)]
    b = np.c_[rng.uniform(0, 5, 2000), rng.uniform(0, 4, 2000), np.zeros(2000)]
    fa = flags(a, np.full(4000, GROUND, np.uint8), b, np.full(2000, GROUND, np.uint8), 0.2, surface=True)
    beyond = a[:, 0] > 6.5
    assert (fa[beyond] == IGNORED).all()
    assert (fa[a[:, 0] < 4.5] == UNCHANGED).all()
    # the nearest rule alone calls it change
    assert (
        flags(a, np.full(4000, GROUND, np.uint8), b, np.full(2000, GROUND, np.uint8), 0.2, False)[beyond]
        == CHANGED
    ).all()


def test_ground_beside_a_new_worker_is_not_changed_by_its_nearest_point():
    # the same ground in both scenes; in B a worker stands on it: ground points of A whose nearest point
    # of B is the worker's foot still find B's ground within the radius
    rng = np.random.default_rng(5)
    a = plane(rng, 8_000, size=10.0, noise=0.005)
    b_ground = plane(rng, 8_000, size=10.0, noise=0.005)
    foot = np.c_[rng.uniform(4.8, 5.2, 300), rng.uniform(4.8, 5.2, 300), rng.uniform(0.0, 1.8, 300)]
    b = np.concatenate([b_ground, foot])
    bc = np.r_[np.full(len(b_ground), GROUND, np.uint8), np.full(len(foot), TAX.id_of("worker"), np.uint8)]
    ac = np.full(len(a), GROUND, np.uint8)
    near_foot = np.hypot(a[:, 0] - 5.0, a[:, 1] - 5.0) < 0.4
    assert near_foot.sum() > 20
    fa = flags(a, ac, b, bc, 0.2, surface=True)
    assert (fa[near_foot] == UNCHANGED).mean() > 0.99
    # the nearest rule compares with the nearest point alone and calls some of them changed
    assert (flags(a, ac, b, bc, 0.2, False)[near_foot] == CHANGED).any()
    # the worker itself is change: no worker in A
    fb = flags(b, bc, a, ac, 0.2, surface=True)
    assert (fb[len(b_ground) :][foot[:, 2] > 0.3] == CHANGED).all()


def test_the_plan_cell_test_agrees_with_a_brute_force_count():
    rng = np.random.default_rng(6)
    b = np.c_[rng.uniform(0, 20, 5000), rng.uniform(0, 10, 5000), rng.uniform(-1, 3, 5000)]
    q = np.c_[rng.uniform(-2, 22, 400), rng.uniform(-2, 12, 400), rng.uniform(-1, 3, 400)]
    test = SurfaceTest(search_m=0.7, lod_floor_m=0.05)
    cells = hidden_from_other(b, q, test)
    bc, qc = np.floor(b[:, :2] / 0.7).astype(int), np.floor(q[:, :2] / 0.7).astype(int)
    for k in range(len(q)):
        mine = (bc == qc[k]).all(axis=1)
        assert cells.covered[k] == mine.any()
        assert cells.hidden[k] == (mine.any() and b[mine, 2].min() > q[k, 2] + 0.05)
        ring = (np.abs(bc - qc[k]) <= 1).all(axis=1)
        over = mine.any() and (b[mine, 2].max() >= q[k, 2] - 0.05 or b[ring, 2].max() > q[k, 2] + 0.7)
        assert cells.above[k] == over
    assert cells.covered.any() and (~cells.covered).any() and cells.hidden.any() and cells.above.any()
    assert (cells.covered & ~cells.above).any()
