"""The renderer on a CUDA device gives what it gives on the CPU (skipped without one; bench/cuda_check.sh
runs these on a GPU machine). Imports only numpy, torch and the renderer, so a bare GPU image runs it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from siteline.errors import RenderError
from siteline.records.params.render import RenderParams
from siteline.render.splats import local_spacing
from siteline.render.zbuffer import render_points

from .helpers import box_scene, oblique_camera

cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine")


def _agree(a, b, hit_tol: float = 0.0) -> None:  # noqa: ANN001
    assert (a.hit != b.hit).mean() <= hit_tol
    moved = a.index != b.index
    assert moved.mean() < 1e-3  # fused multiply-add may move a point that sits on a depth tie
    same = a.hit & b.hit & ~moved
    for name in a.attributes:
        assert np.array_equal(a.attributes[name][same], b.attributes[name][same]), name
    assert np.array_equal(a.rgb[same], b.rgb[same])
    assert np.allclose(a.depth[same], b.depth[same], rtol=1e-5)


@cuda
@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize(("scale", "point_size"), [(1.0, 1), (1.0, 3), (0.5, 5), (0.25, 1)])
def test_cuda_equals_cpu(scale: float, point_size: int, precision: str) -> None:
    xyz, rgb, cls = box_scene(5, 50_000)
    cam = oblique_camera(706, 510)
    s = RenderParams(scale=scale, point_size_px=point_size, precision=precision)
    attrs = {"rgb": rgb, "cls": cls}
    a = render_points(xyz.astype(np.float32), cam, s, attrs)
    b = render_points(xyz.astype(np.float32), cam, s, attrs, device="cuda")
    assert a.coverage > 0.05
    _agree(a, b)


@cuda
@pytest.mark.parametrize(("scale", "fill"), [(1.0, 0), (1.0, 2), (0.5, 3), (0.25, 2)])
def test_cuda_world_splats_and_fill_equal_cpu(scale: float, fill: int) -> None:
    """World splats size each disk from a float32 depth, which fused multiply-add may move across
    a whole pixel for a point or two: the hit masks agree to a thousandth."""
    xyz, rgb, cls = box_scene(5, 50_000)
    spacing = local_spacing(xyz)
    cam = oblique_camera(706, 510)
    s = RenderParams(scale=scale, splat="world", fill_px=fill)
    attrs = {"rgb": rgb, "cls": cls}
    a = render_points(xyz.astype(np.float32), cam, s, attrs, spacing_m=spacing)
    b = render_points(xyz.astype(np.float32), cam, s, attrs, device="cuda", spacing_m=spacing)
    assert a.coverage > 0.3
    _agree(a, b, hit_tol=1e-3)
    assert abs(a.filled_share - b.filled_share) < 1e-3


@cuda
def test_points_already_on_the_device_and_chunks() -> None:
    """Points handed over as CUDA tensors, and split into many projection batches, render the same."""
    xyz, rgb, cls = box_scene(7, 40_000)
    cam = oblique_camera(400, 300)
    whole = render_points(xyz.astype(np.float32), cam, RenderParams(scale=1.0), {"cls": cls}, device="cuda")
    on_device = render_points(
        torch.from_numpy(xyz.astype(np.float32)).cuda(), cam, RenderParams(scale=1.0, chunk_points=7_001),
        {"cls": torch.from_numpy(cls).cuda()}, device="cuda",
    )  # fmt: skip
    assert np.array_equal(whole.hit, on_device.hit)
    assert np.array_equal(whole.index, on_device.index)
    assert np.array_equal(whole.attributes["cls"], on_device.attributes["cls"])


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a CUDA device")
def test_cuda_without_a_device_is_refused() -> None:
    xyz, _, _ = box_scene(1, 1_000)
    with pytest.raises(RenderError, match="torch sees no CUDA device"):
        render_points(xyz.astype(np.float32), oblique_camera(), RenderParams(), device="cuda")
