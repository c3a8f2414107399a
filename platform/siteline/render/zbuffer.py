"""Point splatting with a z-buffer in torch, one code path for CPU and CUDA (DESIGN.md §6).

Points arrive in the site-local frame (float32, metres) with per-point attributes. Each batch is
projected, invalid points (behind the near plane, NaN/inf, off-image) are sent to a dump slot before
any integer cast, and every pixel keeps the minimum of the key (float32 depth bits << 32 | point
index) via ``scatter_reduce_(..., "amin")``: the nearest point wins and equal depths break by the
smaller index, so the output does not depend on the device or the batch size.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
import torch

from siteline.cameras import Camera
from siteline.errors import RenderError
from siteline.render.settings import RenderSettings

EMPTY_KEY = torch.iinfo(torch.int64).max
MAX_POINTS = 2**32 - 1
INDEX_MASK = 0xFFFFFFFF


@dataclass
class RenderResult:
    """Outputs of one render, all (H, W[, C]) numpy arrays on the CPU.

    hit: bool, a point landed. depth: float32 z_cam in metres, NaN where no hit. index: int64 winning
    point index into the input, -1 where no hit. attributes: each input attribute gathered at the
    winner, zero where no hit (check ``hit``). camera: the camera at the render scale.
    """

    camera: Camera
    hit: np.ndarray
    depth: np.ndarray
    index: np.ndarray
    attributes: dict[str, np.ndarray]
    stats: dict[str, float] = field(default_factory=dict)

    @property
    def coverage(self) -> float:
        """Fraction of pixels hit."""
        return float(self.hit.mean()) if self.hit.size else 0.0

    @property
    def rgb(self) -> np.ndarray:
        if "rgb" not in self.attributes:
            raise RenderError("this render was given no 'rgb' attribute.")
        return self.attributes["rgb"]


def disk_offsets(point_size_px: int) -> list[tuple[int, int]]:
    """Pixel offsets (du, dv) covered by a disk of diameter ``point_size_px`` centred on a pixel."""
    r = point_size_px / 2.0
    k = point_size_px // 2
    return [(du, dv) for dv in range(-k, k + 1) for du in range(-k, k + 1) if du * du + dv * dv <= r * r]


def _as_tensor(x: np.ndarray | torch.Tensor) -> torch.Tensor:
    return x if isinstance(x, torch.Tensor) else torch.from_numpy(np.ascontiguousarray(x))


def _check_inputs(xyz: np.ndarray | torch.Tensor, attributes: Mapping[str, np.ndarray | torch.Tensor]) -> int:
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise RenderError(f"points must have shape (N, 3), got {tuple(xyz.shape)}.")
    if xyz.dtype not in (np.float32, torch.float32):
        raise RenderError(
            f"points must be site-local float32, got {xyz.dtype}; georeferenced float64 coordinates go "
            "through siteline.render.render_georeferenced."
        )
    n = int(xyz.shape[0])
    if n > MAX_POINTS:
        raise RenderError(f"{n} points exceed the {MAX_POINTS} a single render indexes; split the cloud.")
    for name, values in attributes.items():
        if values.shape[0] != n:
            raise RenderError(f"attribute {name!r} has {values.shape[0]} rows for {n} points.")
    return n


def _dtype(settings: RenderSettings) -> torch.dtype:
    """The float type projections are computed in."""
    return torch.float64 if settings.precision == "float64" else torch.float32


def _projector(cam: Camera, settings: RenderSettings, dev: torch.device) -> Callable[[torch.Tensor], tuple]:
    """Projection of (M, 3) site-local points through the scaled camera ``cam``: (valid, u, v, z),
    valid where in front of ``near_m`` and within the image widened by half a point (NaN and inf
    fail every comparison, so they are invalid; nothing is cast yet)."""
    W, H = cam.width, cam.height
    dtype = _dtype(settings)
    Rt = torch.as_tensor(cam.R.T, dtype=dtype, device=dev)
    tt = torch.as_tensor(cam.t, dtype=dtype, device=dev)
    fx, fy, cx, cy = cam.fx, cam.fy, cam.cx, cam.cy
    margin = float(settings.point_size_px // 2)

    def project(p: torch.Tensor) -> tuple:
        c = torch.addmm(tt, p.to(dev, non_blocking=True).to(dtype), Rt)  # (M, 3) camera coordinates
        z = c[:, 2]
        inv_z = 1.0 / z
        u = c[:, 0] * inv_z * fx + cx
        v = c[:, 1] * inv_z * fy + cy
        valid = (z > settings.near_m) & (u >= -margin) & (u < W + margin) & (v >= -margin) & (v < H + margin)
        return valid, u, v, z

    return project


def _splat(
    pts: torch.Tensor, cam: Camera, settings: RenderSettings, dev: torch.device, zbuf: torch.Tensor
) -> int:
    """Project ``pts`` (N, 3) site-local through the scaled camera ``cam`` in batches and keep per
    pixel of ``zbuf`` ((H W + 1,) int64; the last slot swallows invalid points) the minimum key
    (float32 depth bits << 32 | point index); return how many points fell in the frustum."""
    W, H = cam.width, cam.height
    npix = W * H
    project = _projector(cam, settings, dev)
    offsets = disk_offsets(settings.point_size_px)
    zero = torch.zeros((), dtype=_dtype(settings), device=dev)
    in_frustum = 0
    n = int(pts.shape[0])
    for start in range(0, n, settings.chunk_points):
        stop = min(n, start + settings.chunk_points)
        valid, u, v, z = project(pts[start:stop])
        in_frustum += int(valid.sum())
        ui = torch.where(valid, u, zero).floor_().to(torch.int64)
        vi = torch.where(valid, v, zero).floor_().to(torch.int64)
        depth_bits = torch.where(valid, z, zero).to(torch.float32).view(torch.int32).to(torch.int64)
        key = (depth_bits << 32) | torch.arange(start, stop, device=dev, dtype=torch.int64)
        if len(offsets) == 1:
            zbuf.scatter_reduce_(0, torch.where(valid, vi * W + ui, npix), key, reduce="amin")
            continue
        # a disk scatters every point several times: drop the invalid ones once, first
        sel = torch.nonzero(valid).squeeze(1)
        ui, vi, key = ui[sel], vi[sel], key[sel]
        for du, dv in offsets:
            uo, vo = ui + du, vi + dv
            ok = (uo >= 0) & (uo < W) & (vo >= 0) & (vo < H)
            zbuf.scatter_reduce_(0, torch.where(ok, vo * W + uo, npix), key, reduce="amin")
    return in_frustum


def coverage_of(
    xyz: np.ndarray | torch.Tensor, camera: Camera, settings: RenderSettings, device: str | torch.device = "cpu"
) -> float:
    """The share of pixels a render of ``xyz`` through ``camera`` with ``settings`` hits (the
    ``coverage`` of :func:`render_points`, exactly): the same projection, each point's disk marked
    on a boolean image widened by half a point, with no depth test and nothing decoded. View
    generation probes thousands of candidates for this one figure."""
    _check_inputs(xyz, {})
    dev = torch.device(device)
    cam = camera.scaled(settings.scale)
    W, H = cam.width, cam.height
    m = settings.point_size_px // 2
    project = _projector(cam, settings, dev)
    centres = torch.zeros((H + 2 * m, W + 2 * m), dtype=torch.bool, device=dev)
    pts = _as_tensor(xyz)
    for start in range(0, int(pts.shape[0]), settings.chunk_points):
        valid, u, v, _ = project(pts[start : start + settings.chunk_points])
        ui = u[valid].floor_().to(torch.int64) + m
        vi = v[valid].floor_().to(torch.int64) + m
        centres[vi, ui] = True
    hit = torch.zeros((H, W), dtype=torch.bool, device=dev)
    for du, dv in disk_offsets(settings.point_size_px):  # pixel (x, y) is hit by a centre at (x - du, y - dv)
        hit |= centres[m - dv : m - dv + H, m - du : m - du + W]
    return int(hit.sum()) / hit.numel() if hit.numel() else 0.0  # as numpy's mean of the hit mask


def _decode(
    zbuf: torch.Tensor, W: int, H: int, attributes: Mapping[str, np.ndarray | torch.Tensor]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(hit, depth, index, attributes) images of a filled z-buffer. Only hit pixels are decoded and
    moved, assembled with torch on the CPU: index_select / index_copy_ are several times faster than
    numpy fancy indexing for millions of pixels (at full scale most of the buffer may be empty)."""
    npix = W * H
    hit_pix_t = torch.nonzero(zbuf[:npix] != EMPTY_KEY).squeeze(1)
    keys_cpu = zbuf[hit_pix_t].cpu()
    hit_pix = hit_pix_t.cpu()
    winners = keys_cpu & INDEX_MASK
    hit_flat = torch.zeros(npix, dtype=torch.bool)
    hit_flat[hit_pix] = True
    index_flat = torch.full((npix,), -1, dtype=torch.int64).index_copy_(0, hit_pix, winners)
    depth_vals = (keys_cpu >> 32).to(torch.int32).view(torch.float32)
    depth_flat = torch.full((npix,), float("nan"), dtype=torch.float32).index_copy_(0, hit_pix, depth_vals)
    out_attrs: dict[str, np.ndarray] = {}
    for name, values in attributes.items():
        arr = (
            values.cpu()
            if isinstance(values, torch.Tensor)
            else torch.from_numpy(np.ascontiguousarray(values))
        )
        img = torch.zeros((npix, *tuple(arr.shape[1:])), dtype=arr.dtype)
        img.index_copy_(0, hit_pix, arr.index_select(0, winners))
        out_attrs[name] = img.numpy().reshape((H, W, *tuple(arr.shape[1:])))
    hit = hit_flat.numpy().reshape(H, W)
    return hit, depth_flat.numpy().reshape(H, W), index_flat.numpy().reshape(H, W), out_attrs


def render_points(
    xyz: np.ndarray | torch.Tensor,
    camera: Camera,
    settings: RenderSettings | None = None,
    attributes: Mapping[str, np.ndarray | torch.Tensor] | None = None,
    device: str | torch.device = "cpu",
) -> RenderResult:
    """Render site-local points through ``camera`` at ``settings.scale``.

    xyz: (N, 3) float32, site-local metres. attributes: name -> (N,) or (N, C) arrays of any dtype
    (uint8 RGB, uint8 class, bool flags). Returns a :class:`RenderResult` at the scaled camera.
    """
    settings = settings or RenderSettings()
    attributes = dict(attributes or {})
    n = _check_inputs(xyz, attributes)
    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise RenderError("device 'cuda' was asked for but torch sees no CUDA device.")
    cam = camera.scaled(settings.scale)
    t0 = time.perf_counter()
    zbuf = torch.full((cam.width * cam.height + 1,), EMPTY_KEY, dtype=torch.int64, device=dev)
    in_frustum = _splat(_as_tensor(xyz), cam, settings, dev, zbuf)
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)
    t_splat = time.perf_counter() - t0
    hit, depth, index, out_attrs = _decode(zbuf, cam.width, cam.height, attributes)
    stats = {
        "points_read": n,
        "points_in_frustum": in_frustum,
        "coverage": float(hit.mean()) if hit.size else 0.0,
        "seconds": time.perf_counter() - t0,
        "seconds_splat": t_splat,
        "width": cam.width,
        "height": cam.height,
    }
    return RenderResult(camera=cam, hit=hit, depth=depth, index=index, attributes=out_attrs, stats=stats)
