"""Thin surfaces said unsure, never seen through: where the edge trim gives a sparse beam's side to the
ground behind it, the mask ignores the pixel (cause ``unsure_edge``) instead of labelling the changed
beam as the unchanged ground."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from siteline.camera.pinhole import Camera
from siteline.codes import CHANGED as MASK_CHANGED
from siteline.codes import IGNORE as MASK_IGNORE
from siteline.codes import UNCHANGED as MASK_UNCHANGED
from siteline.labels.change import CHANGED, UNCHANGED
from siteline.pairs.render import ignore_causes, pair_mask, sparse_candidates, unsure_edges
from siteline.records.params.render import RenderParams
from siteline.render import zbuffer
from siteline.render.zbuffer import render_points

TRIM = RenderParams(scale=1.0, splat="world", trim_edges=True)
BEAM_Z, CAMERA_Z = 18.0, 31.0


def _scenes(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The earlier scene: ground at 11 points/m2 (random, as a flight samples it); the later: other
    ground samples and a jib 1 m wide at 18 m along y with the same density. xyz and change codes
    of each (the jib changed)."""
    rng = np.random.default_rng(seed)

    def ground(n: int) -> np.ndarray:
        return np.c_[rng.uniform(-20, 20, (n, 2)), np.zeros(n)]

    a = ground(17600)
    jib = np.c_[rng.uniform(-0.5, 0.5, 330), rng.uniform(-15, 15, 330), np.full(330, BEAM_Z)]
    b = np.concatenate([ground(17600), jib])
    code_b = np.r_[np.full(17600, UNCHANGED), np.full(330, CHANGED)].astype(np.uint8)
    return a, np.zeros(len(a), np.uint8) + UNCHANGED, b, code_b


def _camera() -> Camera:
    return Camera.look_at((0.0, 0.0, CAMERA_Z), (0.0, 0.0, 0.0), 400, 300, fx=340.0)


def _true_jib(cam: Camera) -> np.ndarray:
    """Pixels whose centre's ray meets the jib's top (|x| <= 0.5 m at 18 m), exactly."""
    u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    x = (u - cam.cx) / cam.fx * (CAMERA_Z - BEAM_Z)
    y = (v - cam.cy) / cam.fy * (CAMERA_Z - BEAM_Z)
    return (np.abs(x) <= 0.5) & (np.abs(y) <= 15.0)


def _pair(
    scenes: tuple[np.ndarray, ...], cam: Camera, settings: RenderParams, spacing_m: float, unsure: bool = True,
    changed_only: bool = False,
) -> tuple[np.ndarray, dict[str, float]]:  # fmt: skip
    """Both scenes rendered as a pair renders them (its labelled points looked at for sparse
    surfaces, or only its changed ones: ``changed_only``, as before), the mask with unsure edges
    ignored or not, and why each ignored pixel is."""
    a, code_a, b, code_b = scenes
    renders, edges = [], []
    for xyz, code in ((a, code_a), (b, code_b)):
        spacing = np.full(len(xyz), spacing_m, np.float32)
        sparse_of = code == CHANGED if changed_only else sparse_candidates(code)
        r = render_points(xyz.astype(np.float32), cam, settings, {"change": code}, "cpu", spacing, sparse_of)
        renders.append(r)
        edges.append(unsure_edges(r, code))
    ra, rb = renders
    mask = pair_mask(ra.hit, ra.attributes["change"], rb.hit, rb.attributes["change"])
    edge = (edges[0] | edges[1]) & (mask != MASK_IGNORE) & unsure
    mask[edge] = MASK_IGNORE
    return mask, ignore_causes(ra, rb, mask, np.zeros(mask.shape, bool), edge)


def _mask(unsure: bool) -> tuple[np.ndarray, dict[str, float]]:
    return _pair(_scenes(), _camera(), TRIM, 0.3, unsure)


def test_a_sparse_beam_is_not_seen_through_its_sides_are_said_unsure() -> None:
    truth = _true_jib(_camera())
    before, causes_before = _mask(unsure=False)
    after, causes_after = _mask(unsure=True)
    # see-through: the beam's true pixels labelled as the unchanged ground behind it, over the whole
    # beam and over its pixels 3 px or more inside its edge (the outermost ones lie beyond its last
    # samples, where neither the splats nor the tests reach: about half a spacing)
    inner = ndimage.distance_transform_cdt(truth, metric="chessboard") >= 3

    def through(mask: np.ndarray, where: np.ndarray) -> float:
        return float(((mask == MASK_UNCHANGED) & where).sum() / where.sum())

    # trimmed away, or holes (a third of the beam until the trim kept what lies between a line's
    # samples, 2026-11-30)
    assert through(before, truth) > 0.2 and through(before, inner) > 0.1
    assert through(after, truth) <= 0.06 and through(after, inner) <= 0.03
    # what is labelled changed stays the beam's, and only pixels near its sides became unsure
    assert ((after == MASK_CHANGED) & ~truth).sum() <= ((before == MASK_CHANGED) & ~truth).sum()
    near = ndimage.binary_dilation(truth, iterations=12)
    assert ((after == MASK_IGNORE) & (before != MASK_IGNORE) & ~near).sum() == 0
    assert causes_after["unsure_edge"] > 0 and causes_before["unsure_edge"] == 0
    assert sum(causes_after.values()) == pytest.approx(float((after == MASK_IGNORE).mean()))


def test_a_render_without_the_trim_has_no_unsure_edges() -> None:
    _, _, b, code_b = _scenes()
    r = render_points(
        b.astype(np.float32), _camera(), RenderParams(scale=1.0, splat="world"), {"change": code_b},
        spacing_m=np.full(len(b), 0.3, np.float32),
    )  # fmt: skip
    assert r.unsure_of is None and not unsure_edges(r, code_b).any()


POLE_X, POLE_R, POLE_H = 4.0, 0.1, 6.0
POLE_CAMERA = (0.0, -3.0, 4.0)


def _pole_scenes(seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The earlier scene: ground at 80 points/m2; the later: other ground samples and a pole 0.2 m
    wide and 6 m tall at (4, 0) that a flight sampled 0.3-0.9 m apart on its sides, from its foot up
    (the sloped scene's pole had 24 points over 6 m), the pole changed."""
    rng = np.random.default_rng(seed)

    def ground(n: int) -> np.ndarray:
        return np.c_[rng.uniform(-6, 14, n), rng.uniform(-10, 10, n), np.zeros(n)]

    z = np.cumsum(np.r_[rng.uniform(0.05, 0.2), rng.uniform(0.3, 0.9, 12)])
    z = z[z < POLE_H]
    a = rng.uniform(0, 2 * np.pi, len(z))
    pole = np.c_[POLE_X + POLE_R * np.cos(a), POLE_R * np.sin(a), z]
    n = 32000
    b = np.concatenate([ground(n), pole])
    code_b = np.r_[np.full(n, UNCHANGED), np.full(len(pole), CHANGED)].astype(np.uint8)
    return ground(n), np.full(n, UNCHANGED, np.uint8), b, code_b


def _true_pole(cam: Camera) -> np.ndarray:
    """Pixels whose centre's ray meets the pole (a cylinder of radius 0.1 m from 0 to 6 m) before the
    ground, exactly."""
    u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    rays = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u)], -1) @ cam.R
    o = np.asarray(cam.center, float)
    dx, dy = rays[..., 0], rays[..., 1]
    ox, oy = o[0] - POLE_X, o[1]
    qa, qb, qc = dx * dx + dy * dy, 2 * (ox * dx + oy * dy), ox * ox + oy * oy - POLE_R**2
    disc = qb * qb - 4 * qa * qc
    t = (-qb - np.sqrt(np.maximum(disc, 0))) / (2 * np.maximum(qa, 1e-12))
    z = o[2] + t * rays[..., 2]
    return (disc >= 0) & (t > 0) & (z >= 0) & (z <= POLE_H)


def _pole_mask(sparse_surfaces: bool) -> np.ndarray:
    cam = Camera.look_at(POLE_CAMERA, (POLE_X, 0.0, 2.0), 400, 300, fx=300.0)
    return _pair(_pole_scenes(), cam, replace(TRIM, sparse_surfaces=sparse_surfaces), 0.11)[0]


def test_a_sparse_pole_is_not_seen_through_between_its_samples() -> None:
    cam = Camera.look_at(POLE_CAMERA, (POLE_X, 0.0, 2.0), 400, 300, fx=300.0)
    truth = _true_pole(cam)
    assert truth.sum() > 500  # the pole stands large in the view

    def through(mask: np.ndarray) -> float:
        return float(((mask == MASK_UNCHANGED) & truth).sum() / truth.sum())

    # a column's samples never surround a pixel, and its tile's spacing (the ground's 0.11 m) does not
    # reach from one to the next: without the knob the ground is labelled where the pole stands
    before, after = _pole_mask(False), _pole_mask(True)
    assert through(before) > 0.3
    assert through(after) <= 0.05
    assert ((after == MASK_CHANGED) & truth).sum() > 0  # its samples are still drawn and labelled
    # the pixels said unsure lie around the pole, within its samples' reach, not over the ground elsewhere
    new = (after == MASK_IGNORE) & (before != MASK_IGNORE)
    near = ndimage.binary_dilation(truth, iterations=110)  # 2.5 m at the pole's 7 m
    assert (new & ~near).sum() == 0 and new.sum() <= 3 * truth.sum()


def test_a_sparse_pole_that_stayed_is_not_seen_through_to_a_change_behind_it() -> None:
    # both scans hold the pole (each its own samples, unchanged); behind it the earlier scan has a
    # wall taken away before the later one (changed), which shows between the pole's samples
    rng = np.random.default_rng(2)
    a, code_a, b, code_b = _pole_scenes()
    other = _pole_scenes(seed=3)  # other samples of the same pole
    pole_a = other[2][other[3] == CHANGED]
    n = 6000
    wall = np.c_[np.full(n, POLE_X + 2.0), rng.uniform(-3, 3, n), rng.uniform(0, 6, n)]  # 330 points/m2
    a = np.concatenate([a, pole_a, wall])
    code_a = np.r_[code_a, np.full(len(pole_a), UNCHANGED), np.full(n, CHANGED)].astype(np.uint8)
    code_b = np.where(code_b == CHANGED, UNCHANGED, code_b).astype(np.uint8)
    cam = Camera.look_at(POLE_CAMERA, (POLE_X, 0.0, 2.0), 400, 300, fx=300.0)
    truth = _true_pole(cam)
    sparse = replace(TRIM, sparse_surfaces=True)
    before = _pair((a, code_a, b, code_b), cam, sparse, 0.11, changed_only=True)[0]
    after = _pair((a, code_a, b, code_b), cam, sparse, 0.11)[0]

    def changed(mask: np.ndarray) -> float:  # the pole labelled as the change behind it
        return float(((mask == MASK_CHANGED) & truth).sum() / truth.sum())

    assert changed(before) > 0.2  # 29 % when only changed points were looked at (as before)
    assert changed(after) <= 0.05
    assert ((after == MASK_UNCHANGED) & truth).sum() > 0  # its samples are still drawn and labelled


def _beam_scenes(seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The earlier scene: ground at 40 points/m2; the later: other ground samples and a beam 1 m
    square from 17 to 18 m along y, its top flown at 40 points/m2 and its sides at 2.5 (a line
    scanner grazes them), the beam changed."""
    rng = np.random.default_rng(seed)

    def ground(n: int) -> np.ndarray:
        return np.c_[rng.uniform(-20, 20, (n, 2)), np.zeros(n)]

    top = np.c_[rng.uniform(-0.5, 0.5, 1200), rng.uniform(-15, 15, 1200), np.full(1200, BEAM_Z)]
    sides = [
        np.c_[np.full(75, x), rng.uniform(-15, 15, 75), rng.uniform(BEAM_Z - 1, BEAM_Z, 75)]
        for x in (-0.5, 0.5)
    ]
    n = 64000
    b = np.concatenate([ground(n), top, *sides])
    code_b = np.r_[np.full(n, UNCHANGED), np.full(len(b) - n, CHANGED)].astype(np.uint8)
    return ground(n), np.full(n, UNCHANGED, np.uint8), b, code_b


def _true_box(cam: Camera, lo: tuple[float, ...], hi: tuple[float, ...]) -> np.ndarray:
    """Pixels whose centre's ray meets the box ``lo``-``hi`` (metres), exactly (slabs)."""
    u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    rays = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u)], -1) @ cam.R
    o = np.asarray(cam.center, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (np.asarray(lo) - o) / rays, (np.asarray(hi) - o) / rays
    near, far = np.nanmax(np.minimum(t1, t2), -1), np.nanmin(np.maximum(t1, t2), -1)
    return (near <= far) & (far > 0)


def test_a_beams_sparse_side_under_its_dense_top_is_not_seen_through(monkeypatch) -> None:
    # the side shares the larger cells with the top (dense there): only the smaller cells find it
    # sparse; and the ground behind it lies within a tenth of its depth near its foot, where half a
    # sample spacing behind the side is already behind it
    cam = Camera.look_at((-10.0, 0.0, 30.0), (2.0, 0.0, 14.0), 400, 300, fx=300.0)
    truth = _true_box(cam, (-0.5, -15.0, BEAM_Z - 1), (0.5, 15.0, BEAM_Z))
    scenes = _beam_scenes()
    sparse = replace(TRIM, sparse_surfaces=True)

    def through(mask: np.ndarray) -> float:
        return float(((mask == MASK_UNCHANGED) & truth).sum() / truth.sum())

    now = _pair(scenes, cam, sparse, 0.16)[0]
    monkeypatch.setattr(zbuffer, "SPARSE_CELLS", (4.0,))
    larger_cells = _pair(scenes, cam, sparse, 0.16)[0]
    monkeypatch.setattr(zbuffer, "BEHIND_SPACINGS", 1e3)  # nothing is behind a sparse sample
    nothing_behind = _pair(scenes, cam, sparse, 0.16)[0]
    assert truth.sum() > 5000
    assert through(nothing_behind) > 0.15
    assert through(now) <= 0.04 and through(larger_cells) > 1.5 * through(now)
    assert ((now == MASK_CHANGED) & truth).sum() > 0.3 * truth.sum()  # the beam is still drawn and labelled
    new = (now == MASK_IGNORE) & (nothing_behind != MASK_IGNORE)
    assert (new & ~ndimage.binary_dilation(truth, iterations=20)).sum() == 0  # unsure only around the beam


def _panel_taken_away(
    seed: int = 3,
) -> tuple[list[tuple[np.ndarray, np.ndarray, np.ndarray]], Camera, np.ndarray]:
    """The sloped scene's fence panel in small: ground at 80 points/m2 (random, 0.11 m apart) with a
    panel 2.5 m wide and 2 m high standing on it (0.24 m jittered samples) in the earlier scan, other
    ground samples where it stood in the later; a camera 54 m away looking down at 15 degrees (6.5 px
    a metre: the ground's disks are round where the ground is seen foreshortened). Per scan (xyz, spacings, change codes), the camera and the panel's true pixels."""
    rng = np.random.default_rng(seed)

    def ground() -> np.ndarray:
        n = 80 * 30 * 30
        return np.c_[rng.uniform(-15, 15, (n, 2)), np.zeros(n)]

    gx, gz = np.meshgrid(np.arange(-1.13, 1.2, 0.24), np.arange(0.1, 2.0, 0.24))
    panel = np.c_[gx.ravel(), np.zeros(gx.size), gz.ravel()]
    panel[:, [0, 2]] += rng.uniform(-0.08, 0.08, (len(panel), 2))
    before, after = np.concatenate([ground(), panel]), ground()
    scans = [
        (before, np.r_[np.full(len(before) - len(panel), 0.11), np.full(len(panel), 0.24)].astype(np.float32),
         np.r_[np.full(len(before) - len(panel), UNCHANGED), np.full(len(panel), CHANGED)].astype(np.uint8)),
        (after, np.full(len(after), 0.11, np.float32), np.full(len(after), UNCHANGED, np.uint8)),
    ]  # fmt: skip
    cam = Camera.look_at((0.0, -52.0, 14.0), (0.0, 0.0, 1.0), 160, 120, fx=350.0)
    u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    rays = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u)], -1) @ cam.R
    t = -cam.center[1] / rays[..., 1]
    hit = cam.center + t[..., None] * rays
    truth = (np.abs(hit[..., 0]) <= 1.25) & (hit[..., 2] >= 0.0) & (hit[..., 2] <= 2.0)
    return scans, cam, truth


def test_the_ground_before_a_panel_taken_away_does_not_take_its_foot(monkeypatch) -> None:
    # the ground's disks in front of the panel's foot reach over its bottom rows: a pixel of an
    # unchanged surface next to a farther changed one is unsure, never the ground in the panel's place
    scans, cam, truth = _panel_taken_away()
    from siteline.pairs import render as pair_render

    def mask() -> np.ndarray:
        renders, edges = [], []
        for xyz, spacing, code in scans:
            r = render_points(
                xyz.astype(np.float32), cam, TRIM, {"change": code}, "cpu", spacing, code == CHANGED
            )
            renders.append(r)
            edges.append(unsure_edges(r, code))
        m = pair_mask(
            renders[0].hit, renders[0].attributes["change"], renders[1].hit, renders[1].attributes["change"]
        )
        m[(edges[0] | edges[1]) & (m != MASK_IGNORE)] = MASK_IGNORE
        return m

    after = mask()
    monkeypatch.setattr(pair_render, "occluding_rims", lambda r: np.zeros(r.hit.shape, bool))
    before = mask()
    assert truth.sum() > 150

    def through(m: np.ndarray) -> float:
        return float(((m == MASK_UNCHANGED) & truth).sum() / truth.sum())

    assert through(before) > 0.05  # its bottom row labelled as the ground (7-8 % of it)
    assert through(after) <= 0.02
    assert ((after == MASK_CHANGED) & truth).sum() >= 0.6 * truth.sum()  # the panel itself stays changed
    # what became unsure lies on the panel's rim, a pixel from it
    rim = ndimage.binary_dilation(truth, iterations=2) & ~ndimage.binary_erosion(truth, iterations=2)
    newly = (after == MASK_IGNORE) & (before != MASK_IGNORE)
    assert newly.any() and (newly & ~rim).sum() <= 0.1 * newly.sum()
