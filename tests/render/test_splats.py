"""World splats and the gap fill: a point's disk follows its spacing seen from the camera, a nearer
surface still hides a farther one, gaps between the points of one surface are filled from that
surface while regions with no surface stay empty, and the result does not depend on the batch."""

from __future__ import annotations

import numpy as np
import pytest

from siteline.camera.pinhole import Camera
from siteline.errors import RenderError
from siteline.records.params.render import RenderParams
from siteline.render.fill import fill_gaps
from siteline.render.splats import diameters_px, disk_offsets, local_spacing, surface_spacing
from siteline.render.zbuffer import coverage_of, render_points

from .helpers import box_scene, oblique_camera, plane_points

WORLD = RenderParams(scale=1.0, splat="world")
FIXED = RenderParams(scale=1.0)


def _jittered_plane(z: float, half: float, step: float, seed: int = 0) -> np.ndarray:
    """A horizontal plane sampled one point per ``step`` cell at a random place in it (as the level
    of detail keeps one point per cube)."""
    rng = np.random.default_rng(seed)
    g = plane_points(z, half, step)
    g[:, :2] += rng.uniform(-step / 2, step / 2, (len(g), 2))
    return g


def _ground_view(width: int = 200, height: int = 150) -> Camera:
    """Looking down at 40 degrees over a plane: near ground at the bottom, far at the top."""
    return Camera.look_at((0.0, -30.0, 25.0), (0.0, 0.0, 0.0), width, height, fx=0.9 * width)


def test_diameter_follows_spacing_over_depth() -> None:
    import torch

    z = torch.tensor([5.0, 10.0, 20.0, 80.0, 1e4])
    spacing = torch.full((5,), 0.1)
    d = diameters_px(
        spacing, z, 400.0, RenderParams(scale=1.0, splat="world", point_size_px=1, splat_max_px=15)
    )
    # 2 x 0.1 m x 400 px / z, rounded up, between the point size and splat_max_px
    assert d.tolist() == [15, 8, 4, 1, 1]
    fixed = diameters_px(spacing, z, 400.0, RenderParams(scale=1.0, point_size_px=3))
    assert fixed.tolist() == [3] * 5


def test_one_point_covers_its_world_footprint() -> None:
    cam = Camera.look_at((0.0, 0.0, 10.0), (0.0, 0.0, 0.0), 41, 41, fx=40.0)
    one = np.array([[0.0, 0.0, 0.0]], np.float32)
    r = render_points(one, cam, WORLD, spacing_m=np.array([1.0], np.float32))
    # 2 x 1 m x 40 px / 10 m = 8 px across
    assert r.hit.sum() == len(disk_offsets(8))
    assert r.depth[r.hit].max() == pytest.approx(10.0)  # the point's own depth, not the splat's rim


def test_world_splats_close_a_sparse_plane_where_fixed_disks_leave_dots() -> None:
    pts = _jittered_plane(0.0, 60.0, 0.5).astype(np.float32)
    cam = _ground_view()
    spacing = np.full(len(pts), 0.5, np.float32)
    fixed = render_points(pts, cam, FIXED)
    world = render_points(pts, cam, WORLD, spacing_m=spacing)
    ground = world.hit  # the plane fills the lower image; the sky above it stays empty
    assert fixed.coverage < 0.5 * world.coverage
    rows = np.flatnonzero(ground.any(axis=1))
    body = ground[rows[5] : rows[-1] + 1]
    assert body.mean() > 0.97
    assert not world.hit[: rows[0]].any()


def test_a_nearer_sparse_surface_hides_a_farther_dense_one() -> None:
    cam = Camera.look_at((0.0, 0.0, 30.0), (0.0, 0.0, 0.0), 120, 120, fx=120.0)
    far = plane_points(0.0, 20.0, 0.05)
    near = _jittered_plane(10.0, 4.0, 0.4, seed=1)
    pts = np.concatenate([far, near]).astype(np.float32)
    spacing = np.r_[np.full(len(far), 0.05), np.full(len(near), 0.4)].astype(np.float32)
    label = np.r_[np.zeros(len(far), np.uint8), np.ones(len(near), np.uint8)]
    fixed = render_points(pts, cam, FIXED, {"label": label})
    world = render_points(pts, cam, WORLD, {"label": label}, spacing_m=spacing)
    inner = slice(35, 85)  # inside the near square's image (+-4 m at 20 m: +-24 px about 60)
    assert (fixed.attributes["label"][inner, inner] == 0).mean() > 0.3  # the far plane shows through
    assert (world.attributes["label"][inner, inner] == 1).all()


def test_world_render_does_not_depend_on_the_batch() -> None:
    xyz, rgb, _ = box_scene(3, 20_000)
    spacing = local_spacing(xyz)
    cam = oblique_camera(300, 220)
    s = RenderParams(scale=1.0, splat="world", fill_px=2)
    a = render_points(xyz.astype(np.float32), cam, s, {"rgb": rgb}, spacing_m=spacing)
    b = render_points(
        xyz.astype(np.float32), cam, RenderParams(scale=1.0, splat="world", fill_px=2, chunk_points=1_777),
        {"rgb": rgb}, spacing_m=spacing,
    )  # fmt: skip
    assert np.array_equal(a.index, b.index) and np.array_equal(a.filled, b.filled)
    assert np.array_equal(a.rgb, b.rgb)


def test_world_splats_need_a_spacing_per_point() -> None:
    pts = np.zeros((4, 3), np.float32)
    with pytest.raises(RenderError, match="spacing"):
        render_points(pts, oblique_camera(), WORLD)
    with pytest.raises(RenderError, match="one per point"):
        render_points(pts, oblique_camera(), WORLD, spacing_m=np.ones(3, np.float32))


@pytest.mark.parametrize(
    "bad", [{"splat": "round"}, {"fill_px": -1}, {"fill_px": 9}, {"splat_max_px": 1, "point_size_px": 3}]
)
def test_bad_splat_settings_are_refused(bad: dict) -> None:
    with pytest.raises(RenderError):
        RenderParams(**bad)


def test_coverage_probe_equals_the_render_before_the_fill() -> None:
    xyz, _, cls = box_scene(2, 30_000)
    spacing = local_spacing(xyz)
    cam = oblique_camera(320, 240)
    r = render_points(xyz.astype(np.float32), cam, WORLD, spacing_m=spacing)
    kept = cls != 2
    cov = coverage_of(xyz.astype(np.float32), cam, WORLD, spacing_m=spacing, kept=kept)
    assert cov.hit == r.coverage
    only_kept = render_points(xyz[kept].astype(np.float32), cam, WORLD, spacing_m=spacing[kept])
    assert cov.kept == only_kept.coverage


# --- the gap fill, on hand-made z-buffers -------------------------------------------------------------


def _buffers(depth: np.ndarray) -> tuple:
    """(index, depth) tensors of a render whose pixel k holds point k at ``depth`` (NaN: no point)."""
    import torch

    d = torch.from_numpy(np.nan_to_num(depth, nan=0.0).astype(np.float32).ravel())
    idx = torch.arange(depth.size, dtype=torch.int64)
    return torch.where(torch.from_numpy(np.isfinite(depth).ravel()), idx, -1), d


def test_fill_closes_a_hole_from_its_nearest_neighbour() -> None:
    depth = np.full((11, 11), 10.0)
    depth[4:7, 5] = np.nan  # a 3 px gap inside a surface
    index, d = _buffers(depth)
    out, new_depth, filled = fill_gaps(index, d, 11, 11, 2)
    f = filled.numpy().reshape(11, 11)
    assert f.sum() == 3 and f[4:7, 5].all()
    # each took the point of a pixel beside it (left, ties to the lower pixel number)
    assert out.numpy().reshape(11, 11)[5, 5] == 5 * 11 + 4
    assert np.allclose(new_depth.numpy().reshape(11, 11)[4:7, 5], 10.0)


def test_fill_never_grows_a_surface_past_its_edge() -> None:
    depth = np.full((20, 20), np.nan)
    depth[10:, :] = 10.0  # ground below, sky above
    depth[12, 7] = np.nan  # and one gap in the ground
    index, d = _buffers(depth)
    _, _, filled = fill_gaps(index, d, 20, 20, 3)
    f = filled.numpy().reshape(20, 20)
    assert f[12, 7] and f.sum() == 1


def test_fill_does_not_bridge_two_surfaces_apart_in_depth() -> None:
    depth = np.full((15, 15), 10.0)
    depth[:, 8:] = 40.0  # a far wall beside a near one
    depth[7, 7] = np.nan  # on the near side, at the edge: its right is the far surface
    depth[3, 11] = np.nan  # inside the far surface
    index, d = _buffers(depth)
    out, _, filled = fill_gaps(index, d, 15, 15, 2)
    f = filled.numpy().reshape(15, 15)
    o = out.numpy().reshape(15, 15)
    assert f[3, 11] and o[3, 11] // 15 in (2, 3, 4) and o[3, 11] % 15 >= 8  # from the far surface
    assert not f[7, 7]  # the near surface lies on one side only


def test_fill_hides_a_far_point_seen_through_a_gap() -> None:
    depth = np.full((11, 11), 10.0)
    depth[5, 5] = 50.0  # a far point showing through a hole in the near surface
    index, d = _buffers(depth)
    out, new_depth, filled = fill_gaps(index, d, 11, 11, 2)
    assert filled.numpy().reshape(11, 11)[5, 5]
    assert new_depth.numpy().reshape(11, 11)[5, 5] == 10.0
    assert out.numpy().reshape(11, 11)[5, 5] != 5 * 11 + 5


def test_fill_zero_changes_nothing() -> None:
    depth = np.full((6, 6), 10.0)
    depth[2, 2] = np.nan
    index, d = _buffers(depth)
    out, _, filled = fill_gaps(index, d, 6, 6, 0)
    assert not filled.any() and np.array_equal(out.numpy(), index.numpy())


def test_world_splats_of_no_points_render_empty() -> None:
    r = render_points(np.zeros((0, 3), np.float32), oblique_camera(), RenderParams(splat="world", fill_px=2),
                      spacing_m=np.zeros(0, np.float32))  # fmt: skip
    assert not r.hit.any() and np.isnan(r.depth).all() and r.filled_share == 0.0


@pytest.mark.parametrize("fill", [0, 2])
def test_the_cpu_kernels_draw_what_the_tensor_code_draws(monkeypatch, fill) -> None:
    """On the CPU the disks are drawn by compiled loops; the tensor code (what CUDA runs) gives the
    same keys: the same winners, depths and coverage, fixed and world splats alike."""
    import siteline.render.zbuffer as zb

    xyz, rgb, cls = box_scene(4, 30_000)
    spacing = local_spacing(xyz)
    cam = oblique_camera(400, 300)
    kept = cls != 2
    for s in (
        RenderParams(scale=1.0, point_size_px=3, fill_px=fill),
        RenderParams(scale=1.0, splat="world", fill_px=fill),
    ):
        compiled = render_points(xyz.astype(np.float32), cam, s, {"rgb": rgb}, spacing_m=spacing)
        cov = coverage_of(xyz.astype(np.float32), cam, s, spacing_m=spacing, kept=kept)
        monkeypatch.setattr(zb, "CPU_KERNELS", False)
        tensor = render_points(xyz.astype(np.float32), cam, s, {"rgb": rgb}, spacing_m=spacing)
        assert coverage_of(xyz.astype(np.float32), cam, s, spacing_m=spacing, kept=kept) == cov
        monkeypatch.setattr(zb, "CPU_KERNELS", True)
        assert np.array_equal(compiled.index, tensor.index) and np.array_equal(compiled.filled, tensor.filled)
        assert np.array_equal(compiled.depth, tensor.depth, equal_nan=True)


def test_the_compiled_fill_fills_what_the_tensor_fill_fills() -> None:
    """Random renders with gaps and see-through pixels: the CPU's compiled fill and the tensor fill
    (what CUDA runs) fill the same pixels from the same points."""
    import torch

    rng = np.random.default_rng(5)
    for _ in range(20):
        h, w = (int(v) for v in rng.integers(5, 60, 2))
        depth = np.where(rng.random((h, w)) < 0.8, rng.choice([10.0, 10.5, 30.0], (h, w)), np.nan)
        index, d = _buffers(depth)
        for r in (1, 2, 3):
            a = fill_gaps(index.clone(), d.clone(), w, h, r, compiled=True)
            b = fill_gaps(index.clone(), d.clone(), w, h, r, compiled=False)
            assert torch.equal(a[0], b[0]) and torch.equal(a[2], b[2])
            assert torch.equal(torch.where(a[0] >= 0, a[1], 0), torch.where(b[0] >= 0, b[1], 0))


@pytest.mark.parametrize("offset", [(0.0, 0.0), (-300.37, 712.91)])
def test_surface_spacing_finds_a_sparse_column_and_leaves_dense_ground(offset: tuple[float, float]) -> None:
    """Ground 0.1 m apart keeps its spacing; a column of points 0.5 m apart standing on it (a pole a
    flight sampled) gets its own, within a factor of about two, whatever the column's place against
    the cells (it straddles a cell edge at the origin) and on either side of the site's origin."""
    g = np.arange(0.0, 10.0, 0.1)
    gx, gy = np.meshgrid(g, g)
    ground = np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]
    z = np.arange(1.0, 7.0, 0.5)
    column = np.c_[np.full(len(z), 4.0), np.full(len(z), 4.0), z]
    xyz = np.concatenate([ground, column]) + [offset[0], offset[1], 0.0]
    given = np.full(len(xyz), 0.1, np.float32)
    own = surface_spacing(xyz.astype(np.float32), given)
    assert own.dtype == np.float32 and own.shape == given.shape
    assert np.array_equal(own[: len(ground)], given[: len(ground)])
    assert 0.4 <= float(np.median(own[len(ground) :])) <= 1.2
    # a lone point has no surface to say anything of: it keeps its spacing
    lone = surface_spacing(np.array([[50.0, 50.0, 9.0]], np.float32), np.array([0.1], np.float32))
    assert lone.tolist() == pytest.approx([0.1])
    assert surface_spacing(np.zeros((0, 3), np.float32), np.zeros(0, np.float32)).shape == (0,)


def test_cell_counts_are_exact_under_their_cap_for_few_points_named_or_most() -> None:
    """The compiled cell count (siteline.render.kernels.cell_counts) against a count by np.unique:
    the same wherever under the cap, at least the cap elsewhere, whether a few points are named (counted
    among themselves, then over every point behind a filter) or most (one count over every point)."""
    from siteline.render import kernels

    rng = np.random.default_rng(5)
    xyz = np.concatenate([rng.uniform(-40, 40, (30_000, 3)) * [1, 1, 0.05], rng.uniform(-40, 40, (300, 3))])
    xyz = xyz.astype(np.float32)
    level = rng.choice(np.array([-2, -1, 0, 1]), len(xyz)).astype(np.int64)
    cap = rng.integers(1, 30, len(xyz)).astype(np.int64)

    def truth(shift: int) -> np.ndarray:
        half = np.floor(xyz * np.exp2(-level)[:, None].astype(np.float32)).astype(np.int64)
        cells = np.c_[(half + shift) >> 1, level]
        _, inverse, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
        return counts[inverse.ravel()]

    want = np.maximum(truth(0), truth(1))
    for which in (np.arange(0, len(xyz), 7), np.arange(len(xyz))):  # few named, most named
        got = kernels.cell_counts(xyz, level, which, cap[which])
        under = want[which] < cap[which]
        assert under.sum() > 100 and (~under).sum() > 100
        assert np.array_equal(got[under], want[which][under]) and (got[~under] >= cap[which][~under]).all()
