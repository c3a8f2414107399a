"""Every change seen: a pair's changed regions, and views planned so that each is in enough of them."""

from __future__ import annotations

import numpy as np
import pytest

from siteline.camera.pinhole import Camera
from siteline.errors import ViewsError
from siteline.labels.regions import region_ids
from siteline.pairs.regions import changes_of
from siteline.records.pairs import ChangedRegion, ChangesSeen, ViewStrategy
from siteline.records.params.render import RenderParams
from siteline.records.params.views import ViewParams
from siteline.render.zbuffer import render_points
from siteline.views.changes import framed_pixels, shown_pixels
from siteline.views.generate import NamedCamera, SyntheticView, ViewSet, cover_changes, generate_views
from siteline.views.ground import fit_ground_plane
from siteline.views.sources import ArrayPointSource

FENCE = [(-70.0, -70.0), (70.0, -70.0), (70.0, 70.0), (-70.0, 70.0)]
PARAMS = ViewParams(
    scale=0.5, point_size_px=3, depth_probe_scale=0.25, min_coverage=0.3, views=12, change_views=0
)


def _box(
    rng: np.random.Generator, lo: tuple[float, float, float], hi: tuple[float, float, float], per_m2: float
) -> np.ndarray:
    """Points on the five visible faces of a box (no bottom), ``per_m2`` a square metre."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    faces = [
        ((x0, x1), (y0, y1), (z1, z1)),
        ((x0, x0), (y0, y1), (z0, z1)), ((x1, x1), (y0, y1), (z0, z1)),
        ((x0, x1), (y0, y0), (z0, z1)), ((x0, x1), (y1, y1), (z0, z1)),
    ]  # fmt: skip
    out = []
    for (ax, bx), (ay, by), (az, bz) in faces:
        area = max(bx - ax, 1e-9) * max(by - ay, 1e-9) * max(bz - az, 1e-9)
        area /= min(max(bx - ax, 1e-9), max(by - ay, 1e-9), max(bz - az, 1e-9))
        n = int(area * per_m2)
        out.append(np.c_[rng.uniform(ax, bx, n), rng.uniform(ay, by, n), rng.uniform(az, bz, n)])
    return np.concatenate(out)


def _site() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Ground 140 x 140 m, a 16 x 16 x 12 m building, and the changes: a container in a corner few
    views frame, a box inside the building (hidden from every camera), and a small far patch."""
    rng = np.random.default_rng(0)
    ground = np.c_[rng.uniform(-70, 70, (80000, 2)), rng.normal(0.0, 0.02, 80000)]
    building = _box(rng, (-8, -8, 0), (8, 8, 12), 40)
    changes = {
        "container": _box(rng, (-58, 50, 0), (-52, 52.5, 2.6), 40),
        "inside": _box(rng, (-2, -2, 3), (2, 2, 6), 40),
        "patch": np.c_[rng.uniform(66.05, 66.45, (30, 2)), np.full(30, 0.05)],  # one 0.5 m cell
    }
    scene = np.concatenate([ground, building, changes["container"], changes["inside"], changes["patch"]])
    return scene, changes


def _cameras() -> list[NamedCamera]:
    spots = [(-40, -40), (40, -40), (40, 40), (0, -50), (50, 0), (10, 30), (-30, 0), (20, -10)]
    return [
        NamedCamera(
            f"DJI_{i:04d}.JPG", Camera.look_at((x, y, 45.0), (0.5 * x, 0.5 * y, 0.0), 640, 480, fx=520.0)
        )
        for i, (x, y) in enumerate(spots)
    ]


def _container_pixels(scene: np.ndarray, container: np.ndarray, camera: Camera) -> int:
    """The container's pixels in a render of the whole scene (the renderer's z-buffer, not the
    planner's estimate)."""
    lo, hi = container.min(axis=0) - 1e-6, container.max(axis=0) + 1e-6
    rest = scene[~np.all((scene >= lo) & (scene <= hi), axis=1)]  # the scene without the container
    xyz = np.concatenate([rest, container]).astype(np.float32)
    flag = np.r_[np.zeros(len(rest), bool), np.ones(len(container), bool)]
    r = render_points(xyz, camera, RenderParams(scale=0.5, point_size_px=3), {"c": flag})
    return int((r.hit & r.attributes["c"]).sum())


def test_regions_are_numbered_by_size_and_link_touching_cells() -> None:
    rng = np.random.default_rng(1)
    big = rng.uniform(0, 3, (500, 3))
    small = rng.uniform(10, 10.5, (40, 3))
    ids = region_ids(np.concatenate([small, big]), 0.5)
    assert set(ids[:40]) == {1} and set(ids[40:]) == {0}
    assert region_ids(np.zeros((0, 3)), 0.5).shape == (0,)


def test_changed_regions_say_their_scenes_and_surface_whatever_the_density() -> None:
    rng = np.random.default_rng(2)

    def patch(x0: float, per_m2: float) -> np.ndarray:
        n = int(16 * per_m2)
        return np.c_[rng.uniform(x0, x0 + 4, n), rng.uniform(0, 4, n), np.full(n, 0.1)]

    moved_from, moved_to = patch(0.0, 40), patch(10.0, 40)
    grown_t1, grown_t2 = patch(30.0, 40), patch(30.5, 40)
    speck = np.c_[rng.uniform(50, 50.4, (5, 2)), np.full(5, 0.1)]
    found = changes_of(
        [("t1", np.concatenate([moved_from, grown_t1, speck])), ("t2", np.concatenate([moved_to, grown_t2]))],
        None,
        1.0,
    )
    by_x = {round(r.center_m[0]): r for r in found.regions}
    assert len(found.regions) == 3 and found.smaller == 1
    assert by_x[2].sides == ("t1",) and by_x[12].sides == ("t2",) and by_x[32].sides == ("t1", "t2")
    assert [r.id for r in found.regions] == [1, 2, 3] and found.regions[0].area_m2 >= found.regions[1].area_m2
    for x0 in (2, 12):
        assert 14.0 <= by_x[x0].area_m2 <= 20.0
    # the same patch 100x denser: the same surface
    dense = changes_of([("t1", patch(0.0, 4000))], None, 1.0)
    assert dense.regions[0].area_m2 == pytest.approx(by_x[2].area_m2, rel=0.15)
    assert np.isclose(found.sample.area_m2[found.sample.region == 0].sum(), found.regions[0].area_m2)
    outside = changes_of([("t2", moved_to)], [(-5.0, -5.0), (5.0, -5.0), (5.0, 5.0), (-5.0, 5.0)], 1.0)
    assert not outside.sample.inside[0]


def test_a_region_behind_a_wall_is_framed_but_not_shown() -> None:
    rng = np.random.default_rng(3)
    ground = np.c_[rng.uniform(-20, 20, (20000, 2)), np.zeros(20000)]
    wall = np.c_[np.full(4000, 5.0), rng.uniform(-6, 6, 4000), rng.uniform(0, 8, 4000)]
    behind = np.c_[rng.uniform(8, 10, 400), rng.uniform(-1, 1, 400), np.full(400, 1.5)]  # a slab's top
    found = changes_of([("t2", behind)], None, 1.0)
    eye = Camera.look_at((-10.0, 0.0, 2.0), (9.0, 0.0, 1.5), 320, 240, fx=260.0)
    above = Camera.look_at((9.0, -12.0, 20.0), (9.0, 0.0, 1.0), 320, 240, fx=260.0)
    framed = framed_pixels(found.sample, [eye, above], 1.0)
    assert framed[0, 0] > 500 and framed[1, 0] > 500
    scene = np.concatenate([ground, wall, behind])
    assert shown_pixels(found.sample, scene, eye, 1.0)[0] < 0.05 * framed[0, 0]
    assert shown_pixels(found.sample, scene, above, 1.0)[0] > 0.8 * framed[1, 0]
    # a region gone from the later scene shows where what is now behind it lies farther
    assert shown_pixels(found.sample, np.concatenate([ground, wall]), above, 1.0)[0] > 0.8 * framed[1, 0]


def test_every_change_is_seen_in_the_views_asked_or_said_why() -> None:
    scene, changes = _site()
    plane = fit_ground_plane(scene[np.abs(scene[:, 2]) < 0.1])
    source = ArrayPointSource(scene.astype(np.float32))
    found = changes_of([("t2", np.concatenate(list(changes.values())))], FENCE, 1.0)
    assert len(found.regions) == 2 and found.smaller == 1  # the patch is under 1 m2
    found = changes_of([("t2", np.concatenate(list(changes.values())))], FENCE, 0.2)
    container = next(r for r, reg in enumerate(found.regions) if reg.center_m[0] < -40)
    inside = next(r for r, reg in enumerate(found.regions) if abs(reg.center_m[0]) < 3)
    patch = next(r for r, reg in enumerate(found.regions) if reg.center_m[0] > 60)

    def views(**knobs: float) -> ViewSet:  # the test's site with PARAMS and ``knobs``, the changes given
        return generate_views(
            _cameras(),
            plane,
            FENCE,
            source,
            ViewParams(**{**PARAMS.to_dict(), **knobs}),
            changes=found.sample,
        )

    plain = generate_views(_cameras(), plane, FENCE, source, PARAMS)
    planned = views(change_views=5)
    assert len(plain.views) == len(planned.views) == 12
    # measured by the renderer, not by the planner: the container's pixels in each view
    seen_before = sum(_container_pixels(scene, changes["container"], v.camera) >= 50 for v in plain.views)
    seen_after = sum(_container_pixels(scene, changes["container"], v.camera) >= 50 for v in planned.views)
    assert seen_before < 5 <= seen_after
    assert sum(container in v.shows for v in planned.views) >= 5
    assert container not in planned.unseen
    assert planned.unseen[inside] == "hidden" and planned.unseen[patch] == "too_small"
    assert planned.probed > plain.probed and sum(planned.all_rejected().values()) >= sum(
        plain.all_rejected().values()
    )
    # the sample stays seeded: the same again
    again = views(change_views=5)
    assert [v.to_dict() for v in again.views] == [v.to_dict() for v in planned.views]
    # a budget smaller than the views asked for the change: every view shows it, and it says why not more
    few = views(views=3, change_views=5, change_share=1.0)
    assert len(few.views) == 3 and all(container in v.shows for v in few.views)
    assert few.unseen[container] == "view_budget"
    # at most change_share of the views are chosen for changes: a quarter of 4 is one
    capped = views(views=4, change_views=5, change_share=0.25)
    drawn = generate_views(_cameras(), plane, FENCE, source, ViewParams(**{**PARAMS.to_dict(), "views": 4}))
    kept = {(v.parent, v.strategy) for v in drawn.views}
    assert len(capped.views) == 4 and sum((v.parent, v.strategy) not in kept for v in capped.views) == 1
    assert capped.unseen[container] == "view_budget"


def test_changes_seen_say_which_regions_are_short_and_why() -> None:
    seen = ChangesSeen(5, 50, 1.0, 2, (
        ChangedRegion(1, ("t1", "t2"), 12.5, (1.0, 2.0, 0.5), (4.0, 4.0, 1.0), (0, 1, 2, 3, 4, 5)),
        ChangedRegion(2, ("t2",), 1.4, (30.0, 2.0, 3.0), (0.2, 0.2, 6.0), (2,), "hidden"),
    ))  # fmt: skip
    assert ChangesSeen.from_dict(seen.to_dict()) == seen
    words = seen.summary()
    assert "2 changed regions of 1 m2 or more" in words and "1 shown, 1 in fewer" in words
    assert words.index("#2") < words.index("#1")  # the short ones first
    assert "hidden from every candidate" in words and "2 smaller regions" in words


@pytest.mark.parametrize(
    "knob", [{"change_views": -1}, {"change_min_px": 0}, {"change_min_m2": -1.0}, {"change_share": 1.5}]
)
def test_change_knobs_are_checked(knob: dict[str, float]) -> None:
    with pytest.raises(ViewsError):
        ViewParams(**knob)  # type: ignore[arg-type]


def test_a_region_framed_only_by_views_already_drawn_is_hidden_not_too_small() -> None:
    """Every candidate that frames the slab is already in the sample and none shows it (a wall stands
    between): the region is hidden, and no probe is spent on it."""
    rng = np.random.default_rng(3)
    slab = np.c_[rng.uniform(8, 10, 400), rng.uniform(-1, 1, 400), np.full(400, 1.5)]
    found = changes_of([("t2", slab)], None, 1.0)
    eye = Camera.look_at((-10.0, 0.0, 2.0), (9.0, 0.0, 1.5), 320, 240, fx=260.0)
    view = SyntheticView("cam0", "v0.5", ViewStrategy(0.5, False, 0.0), eye, coverage=0.9)
    params = ViewParams(scale=1.0, views=1, change_views=5, change_share=1.0)

    def judge(v: SyntheticView) -> SyntheticView:
        raise AssertionError(f"{v.strategy} is already drawn; nothing is probed")

    views, unseen = cover_changes([view], [view], found.sample, judge, params)
    assert views == [view] and unseen == {0: "hidden"}
