"""Splits that never move between versions and are never empty while there are views to split."""

from __future__ import annotations

from collections import Counter

from siteline.camera.pinhole import Camera
from siteline.records.pairs import RenderedView, ViewStrategy
from siteline.release.splits import assign_splits


def _view(index: int, x: float, y: float = 0.0, height: float = 50.0) -> RenderedView:
    """A nadir view ``height`` m up: a disc of radius height x 250 / 600 (21 m at 50 m)."""
    cam = Camera.look_at([x, y, height], [x, y, 0.0], 200, 150, 300.0)
    return RenderedView(index, "img", "v1-orig-f0", ViewStrategy(1.0, False, 0.0, central_depth_m=height), 0.9, cam,
                        f"{index:04d}.png", 0.9, 0.9, 0.8, 0.1, 1000)  # fmt: skip


def test_one_pair_is_cut_into_spatial_bands_with_every_split_populated() -> None:
    views = {1: [_view(i, 20.0 * i, height=120.0) for i in range(40)]}  # 800 m of views, 50 m discs
    plan = assign_splits(views, seed=0)
    by = {s: sorted(i for (_, i), sp in plan.of.items() if sp == s) for s in ("train", "val", "test")}
    assert all(by.values()), by
    assert max(by["test"]) < min(by["train"]) and max(by["train"]) < min(by["val"])  # bands, ends apart
    assert plan.rule["max_shared_footprint"] <= 0.5 and plan.left_out  # train views near val/test left out
    assert not set(plan.left_out) & set(plan.of)


def test_items_keep_their_split_and_new_ones_do_not_move_them() -> None:
    first = assign_splits({1: [_view(i, 20.0 * i) for i in range(40)]}, seed=0)
    # a later version: pair 1 gains two views (one at each end), and two new pairs arrive
    later_views = {1: [_view(i, 20.0 * i) for i in range(42)], 2: [_view(i, 5.0 * i) for i in range(6)],
                   3: [_view(i, 7.0 * i) for i in range(6)]}  # fmt: skip
    later = assign_splits(later_views, seed=0, previous=first.of)
    assert all(later.of[item] == split for item, split in first.of.items())
    assert later.of[(1, 40)] == later.of[(1, 39)]  # a new view takes its nearest kept view's split
    new_pairs = {p: {sp for (q, _), sp in later.of.items() if q == p} for p in (2, 3)}
    assert all(len(s) == 1 for s in new_pairs.values())  # a new pair goes whole to one split


def test_three_pairs_or_more_split_by_whole_pairs() -> None:
    views = {p: [_view(i, 10.0 * i) for i in range(5)] for p in range(1, 8)}
    plan = assign_splits(views, seed=3)
    per_pair = {p: {sp for (q, _), sp in plan.of.items() if q == p} for p in views}
    assert all(len(s) == 1 for s in per_pair.values())
    assert set(Counter(next(iter(s)) for s in per_pair.values())) == {"train", "val", "test"}


def test_a_view_held_out_of_train_stays_out_over_three_versions() -> None:
    from siteline.release.splits import LEFT_OUT

    views = {1: [_view(i, 20.0 * i, height=120.0) for i in range(40)]}  # wide discs: neighbours share ground
    plan = assign_splits(views, seed=0)
    held = set(plan.left_out)
    assert held and "max_shared_footprint" in plan.rule
    for version, new_pair in ((2, 2), (3, 3)):  # each later version adds a pair
        previous = dict(plan.of) | dict.fromkeys(plan.left_out, LEFT_OUT)
        views = views | {
            new_pair: [_view(i, 20.0 * i, height=120.0) for i in range(40)]
        }  # the same ground again
        plan = assign_splits(views, seed=0, previous=previous)
        assert held <= set(plan.left_out) and not held & set(plan.of), f"version {version}"
        assert all(plan.of[item] == split for item, split in previous.items() if split != LEFT_OUT)
        assert "max_shared_footprint" in plan.rule  # every version states the figure
