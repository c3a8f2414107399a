"""A pair renders its views in a tour by where they look (consecutive renders share tiles, which the
chunk caches hold); what it makes does not depend on that order."""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from siteline.camera.pinhole import Camera
from siteline.pairs import execute
from siteline.pairs.execute import execute_pair, look_tour
from siteline.pairs.plan import plan_pair
from siteline.records.pairs import ViewStrategy
from siteline.records.params.pairs import PairParams
from siteline.views.generate import SyntheticView
from siteline.views.ground import GroundPlane

FLAT = GroundPlane((0.0, 0.0, 1.0), 0.0)


def _views(n: int, seed: int = 0) -> list[SyntheticView]:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        x, y = rng.uniform(-100, 100, 2)
        tilt = 0.0 if k % 3 else 20.0  # every third looks 20 m off to the side
        cam = Camera.look_at((x, y, 30.0), (x + tilt, y, 0.0), 64, 48, fx=50.0)
        out.append(SyntheticView(f"p{k}", "vertical", ViewStrategy(1.0, False, 0.0), cam))
    return out


def _looks_at(v: SyntheticView) -> np.ndarray:
    hit = FLAT.axis_hit(v.camera.center, v.camera.forward)
    assert hit is not None
    return hit


def test_the_tour_goes_to_the_view_that_looks_nearest_next() -> None:
    views = _views(40)
    tour = look_tour(views, FLAT)
    assert tour[0] is views[0] and sorted(id(v) for v in tour) == sorted(id(v) for v in views)
    for k in range(len(tour) - 1):  # greedy: no view left looks nearer than the next one
        here = _looks_at(tour[k])
        nearest = min(float(np.linalg.norm(_looks_at(v) - here)) for v in tour[k + 1 :])
        assert float(np.linalg.norm(_looks_at(tour[k + 1]) - here)) == nearest

    def length(order: list[SyntheticView]) -> float:
        at = np.array([_looks_at(v) for v in order])
        return float(np.linalg.norm(np.diff(at, axis=0), axis=1).sum())

    assert length(tour) < 0.5 * length(views)
    # a camera looking level is placed where it stands
    level = Camera.look_at((0.0, 0.0, 30.0), (50.0, 0.0, 30.0), 64, 48, fx=50.0)
    views.append(SyntheticView("level", "forward", ViewStrategy(1.0, False, 0.5), level))
    assert len(look_tour(views, FLAT)) == 41 and look_tour(views[:2], FLAT) == views[:2]


def _made(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def test_a_pair_makes_the_same_outputs_in_any_render_order(scenes, tmp_path, monkeypatch) -> None:
    settings, cat = scenes
    params = PairParams(scale=0.25, point_size_px=3, views=6, seed=3, min_coverage=0.3)
    with cat.transaction() as s:
        plan = plan_pair(s, settings.store, 1, params)
    toured = execute_pair(replace(plan, root=str(tmp_path / "toured")), settings.store)
    rendered: list[str] = []

    def backwards(views, ground):  # noqa: ANN001, ANN202
        order = list(reversed(look_tour(views, ground)))
        rendered.extend(v.parent + v.strategy for v in order)
        return order

    monkeypatch.setattr(execute, "look_tour", backwards)
    reversed_ = execute_pair(replace(plan, root=str(tmp_path / "reversed")), settings.store)
    assert len(rendered) == len(toured.views) >= 4
    made, again = _made(tmp_path / "toured"), _made(tmp_path / "reversed")
    assert sum(k.endswith(".png") for k in made) == 3 * len(toured.views)
    assert {k: v for k, v in made.items() if k != "summary.json"} == {
        k: v for k, v in again.items() if k != "summary.json"
    }

    def summary(root: Path) -> dict:  # the labels were made by the first run and reused by the second
        doc = json.loads((root / "summary.json").read_text())
        doc["labels"].pop("seconds", None)
        return doc

    assert summary(tmp_path / "toured") == summary(tmp_path / "reversed")
    assert [v.to_dict() for v in toured.views] == [v.to_dict() for v in reversed_.views]
