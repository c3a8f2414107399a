"""Point splatting with a z-buffer in torch, one code path for CPU and CUDA (DESIGN.md §6).

Points arrive in the site-local frame (float32, metres) with per-point attributes. Each batch is
projected, invalid points (behind the near plane, NaN/inf, off-image) are sent to a dump slot before
any integer cast, and every pixel keeps the minimum of the key (float32 depth bits << 32 | point
index) via ``scatter_reduce_(..., "amin")``: the nearest point wins and equal depths break by the
smaller index, so the output does not depend on the device or the batch size.

A point covers a disk of pixels (siteline.render.splats): the point size, or with world splats its
spacing seen from the camera. A world splat's pixels carry its depth plus a paraboloid that rises
to the splat's world radius at its rim, so where neighbouring splats of one surface overlap each
pixel goes to the point whose centre is nearest, while a surface farther than that radius stays
hidden. The gap fill (siteline.render.fill) then closes what the splats left between the points
of one surface. With ``trim_edges`` a world splat that reaches past its surface's edge gives the
pixels there back to the farther surface behind (siteline.render.edges).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
import torch

from siteline.camera.pinhole import Camera
from siteline.errors import RenderError
from siteline.records.params.render import MAX_SPLAT_PX, RenderParams
from siteline.render import kernels
from siteline.render.edges import see_through, trim_edges
from siteline.render.fill import fill_gaps
from siteline.render.splats import check_spacing, diameters_px, disk_offsets, disk_pixels, surface_spacing

EMPTY_KEY = torch.iinfo(torch.int64).max
MAX_POINTS = 2**32 - 1
INDEX_MASK = 0xFFFFFFFF
# how wide (in its own spacings) a sparse surface's sample reaches when the pixels behind it are said
# unsure: its own spacing is the distance to the farther of its two nearest neighbours, so disks of
# 1.5 of it close the gap to each; the halo beside a pole is 0.75 of its spacing (docs/performance.md)
SPARSE_REACH = 1.5
# a surface is looked at for being sparse in cells of these many of its spacings (siteline.render.splats
# .surface_spacing; the sparser counts): the larger finds a pole's column among ground, the smaller a
# beam's side under its dense top, which shares the larger cells with it (the box scene's jib, 1 m
# square: 12.1 -> 7.3 % of its pixels seen through, docs/performance.md). A render's ``sparse_of``
# says in how many of them (in this order) each point is looked at
SPARSE_CELLS = (4.0, 2.0)
# a winner lies behind a sparse surface's sample (and may be seen between its samples) when it is this
# many of the sample's own spacings farther: half a gap, where its surface may lie; a tenth of the
# depth (siteline.render.fill.SAME_SURFACE), as before, let through the ground a metre or two behind
# a pole or a panel seen from 30 m
BEHIND_SPACINGS = 0.5


@dataclass
class RenderResult:
    """Outputs of one render, all (H, W[, C]) numpy arrays on the CPU.

    hit: bool, a point landed (drawn or filled). depth: float32 z_cam in metres of the winning point,
    NaN where no hit. index: int64 winning point index into the input, -1 where no hit. attributes:
    each input attribute gathered at the winner, zero where no hit (check ``hit``). filled: bool, the
    pixels the gap fill gave a neighbour's point (a subset of ``hit``). unsure_of: int64, the nearer
    point whose surface may lie where a farther one is drawn, -1 elsewhere: where the edge trim gave
    the pixel to the farther surface, the point whose splat reached it, and where the winner shows
    through a nearer surface's hole (siteline.render.edges.see_through), that surface's nearest
    sample; None without the trim. camera: the camera at the render scale.
    """

    camera: Camera
    hit: np.ndarray
    depth: np.ndarray
    index: np.ndarray
    attributes: dict[str, np.ndarray]
    stats: dict[str, float] = field(default_factory=dict)
    filled: np.ndarray | None = None
    unsure_of: np.ndarray | None = None

    @property
    def filled_share(self) -> float:
        """Fraction of pixels the gap fill gave a point."""
        return float(self.filled.mean()) if self.filled is not None and self.filled.size else 0.0

    @property
    def coverage(self) -> float:
        """Fraction of pixels hit."""
        return float(self.hit.mean()) if self.hit.size else 0.0

    @property
    def rgb(self) -> np.ndarray:
        if "rgb" not in self.attributes:
            raise RenderError("this render was given no 'rgb' attribute.")
        return self.attributes["rgb"]


def _as_tensor(x: np.ndarray | torch.Tensor) -> torch.Tensor:
    return x if isinstance(x, torch.Tensor) else torch.from_numpy(np.ascontiguousarray(x))


def _check_inputs(
    xyz: np.ndarray | torch.Tensor,
    attributes: Mapping[str, np.ndarray | torch.Tensor],
    settings: RenderParams,
    spacing_m: np.ndarray | torch.Tensor | None,
) -> int:
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise RenderError(f"points must have shape (N, 3), got {tuple(xyz.shape)}.")
    if xyz.dtype not in (np.float32, torch.float32):
        raise RenderError(
            f"points must be site-local float32, got {xyz.dtype}; georeferenced float64 coordinates go "
            "through siteline.render.georef.render_georeferenced."
        )
    n = int(xyz.shape[0])
    if n > MAX_POINTS:
        raise RenderError(f"{n} points exceed the {MAX_POINTS} a single render indexes; split the cloud.")
    for name, values in attributes.items():
        if values.shape[0] != n:
            raise RenderError(f"attribute {name!r} has {values.shape[0]} rows for {n} points.")
    check_spacing(spacing_m, n, settings)
    return n


def _dtype(settings: RenderParams) -> torch.dtype:
    """The float type projections are computed in."""
    return torch.float64 if settings.precision == "float64" else torch.float32


def _projector(cam: Camera, settings: RenderParams, dev: torch.device) -> Callable[[torch.Tensor], tuple]:
    """Projection of (M, 3) site-local points through the scaled camera ``cam``: (valid, u, v, z),
    valid where in front of ``near_m`` and within the image widened by half the widest splat (NaN and
    inf fail every comparison, so they are invalid; nothing is cast yet)."""
    W, H = cam.width, cam.height
    dtype = _dtype(settings)
    R = torch.as_tensor(cam.R, dtype=dtype, device=dev)
    tt = torch.as_tensor(cam.t, dtype=dtype, device=dev)[:, None]
    fx, fy, cx, cy = cam.fx, cam.fy, cam.cx, cam.cy
    margin = float((settings.splat_max_px if settings.splat == "world" else settings.point_size_px) // 2)

    def project(p: torch.Tensor) -> tuple:
        # (3, M) camera coordinates: a (3, 3) x (3, M) product is several times faster than (M, 3) x (3, 3)
        c = torch.addmm(tt, R, p.to(dev, non_blocking=True).to(dtype).T.contiguous())
        z = c[2]
        inv_z = 1.0 / z
        u = c[0] * inv_z * fx + cx
        v = c[1] * inv_z * fy + cy
        valid = (z > settings.near_m) & (u >= -margin) & (u < W + margin) & (v >= -margin) & (v < H + margin)
        return valid, u, v, z

    return project


def _focal(cam: Camera) -> float:
    """The focal length (pixels) world splats are sized with: the larger axis, so a disk spans its
    spacing in both."""
    return float(max(cam.fx, cam.fy))


# on the CPU, disks are drawn by compiled loops (siteline.render.kernels), which give exactly what the
# tensor code below gives on any device (the tests turn them off to check that)
CPU_KERNELS = True
# a run of at least this many points of one disk diameter is drawn offset by offset (one scatter of
# the whole run per pixel of the disk); shorter runs are drawn as one list of (point, pixel) pairs,
# so many diameters cost a few calls, not one per offset of each
BULK_POINTS = 1 << 15


def _groups(diameters: torch.Tensor) -> list[tuple[int, torch.Tensor | None]]:
    """The points of each disk diameter: ``(diameter, positions)``, positions None when every point
    shares the one diameter."""
    if int(diameters.shape[0]) == 0:
        return []
    values = torch.nonzero(torch.bincount(diameters)).squeeze(1).tolist()  # diameters are small integers
    if len(values) == 1:
        return [(int(values[0]), None)]
    return [(int(d), torch.nonzero(diameters == d).squeeze(1)) for d in values]


def _disk_pixels(
    ui: torch.Tensor, vi: torch.Tensor, diameters: torch.Tensor, cam: Camera, max_diameter_px: int
) -> Iterator[tuple[torch.Tensor | None, torch.Tensor, float | torch.Tensor]]:
    """Every pixel of every point's disk as ``(which, pixel, rho2)``: the points (positions, or None
    for all), the flat pixel each covers (H W, the dump slot, when off the image) and its squared
    distance in pixels from the point's own pixel."""
    W, H = cam.width, cam.height

    def flat(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        return torch.where((u >= 0) & (u < W) & (v >= 0) & (v < H), v * W + u, W * H)

    short = []
    for d, pos in _groups(diameters):
        if pos is not None and len(pos) < BULK_POINTS:
            short.append(pos)
            continue
        gu, gv = (ui, vi) if pos is None else (ui[pos], vi[pos])
        for du, dv in disk_offsets(d):
            yield pos, flat(gu + du, gv + dv), float(du * du + dv * dv)
    if short:
        pos = torch.cat(short)
        for point, du_t, dv_t, rho2_t in disk_pixels(diameters[pos], max_diameter_px):
            which = pos[point]
            yield which, flat(ui[which] + du_t, vi[which] + dv_t), rho2_t.to(torch.float32)


def _take(values: torch.Tensor, which: torch.Tensor | None) -> torch.Tensor:
    return values if which is None else values[which]


def _splat(
    pts: torch.Tensor,
    spacing: torch.Tensor | None,
    cam: Camera,
    settings: RenderParams,
    dev: torch.device,
    zbuf: torch.Tensor,
    depths: torch.Tensor | None = None,
    centres: torch.Tensor | None = None,
) -> int:
    """Project ``pts`` (N, 3) site-local through the scaled camera ``cam`` in batches and keep per
    pixel of ``zbuf`` ((H W + 1,) int64; the last slot swallows invalid points) the minimum key
    (float32 depth bits << 32 | point index); return how many points fell in the frustum. spacing:
    (N,) metres per point, for world splats; depths: (N,) float32, receives each point's camera
    depth when given (a world splat's key holds its depth plus the paraboloid); centres: (H W + 1,)
    int64, receives the keys of the points drawn as one pixel each when given (the edge trim's)."""
    W, H = cam.width, cam.height
    npix = W * H
    project = _projector(cam, settings, dev)
    zero = torch.zeros((), dtype=_dtype(settings), device=dev)
    world = settings.splat == "world"
    in_frustum = 0
    n = int(pts.shape[0])
    for start in range(0, n, settings.chunk_points):
        stop = min(n, start + settings.chunk_points)
        valid, u, v, z = project(pts[start:stop])
        in_frustum += int(valid.sum())
        if depths is not None:
            depths[start:stop] = z.to(torch.float32)
        ui = torch.where(valid, u, zero).floor_().to(torch.int64)
        vi = torch.where(valid, v, zero).floor_().to(torch.int64)
        depth_bits = torch.where(valid, z, zero).to(torch.float32).view(torch.int32).to(torch.int64)
        index = torch.arange(start, stop, device=dev, dtype=torch.int64)
        if centres is not None or (settings.point_size_px == 1 and not world):
            key = (depth_bits << 32) | index
            own = torch.where(valid & (ui >= 0) & (ui < W) & (vi >= 0) & (vi < H), vi * W + ui, npix)
            (zbuf if centres is None else centres).scatter_reduce_(0, own, key, reduce="amin")
            if centres is None:
                continue
        # a disk scatters every point several times: drop the invalid ones once, first
        sel = torch.nonzero(valid).squeeze(1)
        ui, vi, zs, index = ui[sel], vi[sel], z[sel].to(torch.float32), index[sel]
        chunk_spacing = spacing[start:stop][sel] if world and spacing is not None else None
        diameters = diameters_px(chunk_spacing, zs, _focal(cam), settings)
        # world disks rise to their world radius at the rim: (z / f) rho^2 / r metres
        rise = zs / _focal(cam) / (diameters.to(torch.float32) / 2.0) if world else torch.zeros_like(zs)
        if dev.type == "cpu" and CPU_KERNELS:  # one compiled pass over the points (siteline.render.kernels)
            kernels.splat_nearest(
                ui.numpy(),
                vi.numpy(),
                zs.numpy(),
                diameters.numpy(),
                rise.numpy(),
                index.numpy(),
                zbuf.numpy(),
                W,
            )
            continue
        for which, pix, rho2 in _disk_pixels(ui, vi, diameters, cam, settings.splat_max_px):
            z_at = _take(zs, which)
            zk = (
                z_at + _take(rise, which) * rho2
                if world and not (isinstance(rho2, float) and rho2 == 0)
                else z_at
            )
            key = (zk.view(torch.int32).to(torch.int64) << 32) | _take(index, which)
            zbuf.scatter_reduce_(0, pix, key, reduce="amin")
    return in_frustum


class Coverage(NamedTuple):
    """What a probe render covers: ``hit``, the share of pixels any point reaches; ``kept``, the share
    a point marked kept reaches (a class that is not ignored, inside the fence), an upper bound of
    the render's valid share on its own scene."""

    hit: float
    kept: float


def coverage_of(
    xyz: np.ndarray | torch.Tensor,
    camera: Camera,
    settings: RenderParams,
    device: str | torch.device = "cpu",
    spacing_m: np.ndarray | torch.Tensor | None = None,
    kept: np.ndarray | torch.Tensor | None = None,
) -> Coverage:
    """The share of pixels a render of ``xyz`` through ``camera`` with ``settings`` hits before the
    gap fill (the ``coverage`` of :func:`render_points` with ``fill_px`` 0, exactly), and the share
    the points where ``kept`` ((N,) bool; all when None) hit: the same projection and splats, each
    disk marked with no depth test and nothing decoded. View generation probes thousands of
    candidates for these figures. spacing_m: (N,) metres per point, for world splats."""
    _check_inputs(xyz, {}, settings, spacing_m)
    dev = torch.device(device)
    cam = camera.scaled(settings.scale)
    W, H = cam.width, cam.height
    npix = W * H
    project = _projector(cam, settings, dev)
    hit = torch.zeros(npix + 1, dtype=torch.bool, device=dev)  # the last slot: off the image
    hit_kept = torch.zeros(npix + 1, dtype=torch.bool, device=dev)
    on_cpu = dev.type == "cpu" and CPU_KERNELS  # the disks are marked by a compiled loop there
    hit_np, hit_kept_np = np.zeros((H, W), bool), np.zeros((H, W), bool)
    pts = _as_tensor(xyz)
    spacing = None if spacing_m is None else _as_tensor(spacing_m).to(dev)
    keep = None if kept is None else _as_tensor(kept).to(dev)
    for start in range(0, int(pts.shape[0]), settings.chunk_points):
        stop = start + settings.chunk_points
        valid, u, v, z = project(pts[start:stop])
        # no compaction: a point outside the frustum is sent off the image, where its disk lands nowhere
        off = torch.tensor(-(2**40), dtype=torch.int64, device=dev)
        ui = torch.where(valid, u.floor().to(torch.int64), off)
        vi = torch.where(valid, v.floor().to(torch.int64), off)
        zs = torch.where(valid, z, 0).to(torch.float32)
        mine = None if keep is None else keep[start:stop]
        diameters = diameters_px(None if spacing is None else spacing[start:stop], zs, _focal(cam), settings)
        if on_cpu:
            flags = np.ones(len(ui), bool) if mine is None else mine.numpy().astype(bool, copy=False)
            kernels.mark_disks(ui.numpy(), vi.numpy(), diameters.numpy(), flags, hit_np, hit_kept_np)
            continue
        for which, pix, _ in _disk_pixels(ui, vi, diameters, cam, settings.splat_max_px):
            hit[pix] = True
            hit_kept[pix if mine is None else pix[_take(mine, which)]] = True
    if not npix:
        return Coverage(0.0, 0.0)
    if on_cpu:
        return Coverage(int(hit_np.sum()) / npix, int(hit_kept_np.sum()) / npix)
    return Coverage(
        int(hit[:npix].sum()) / npix, int(hit_kept[:npix].sum()) / npix
    )  # as numpy's mean of a mask


def central_depths(xyz: np.ndarray, camera: Camera, scale: float, fraction: float) -> np.ndarray:
    """The depths (metres, float32) of the pixels of the central ``fraction`` of the image (width and
    height) of a one-pixel render of ``xyz`` ((N, 3) float32 site-local) through ``camera`` at
    ``scale``: the nearest point's depth where a point falls, nothing where none does. On the CPU
    (view generation's depth probes)."""
    settings = RenderParams(scale=scale)
    cam = camera.scaled(scale)
    H, W = cam.height, cam.width
    fh, fw = max(1, int(round(H * fraction))), max(1, int(round(W * fraction)))
    top, left = (H - fh) // 2, (W - fw) // 2
    out = np.full((fh, fw), np.inf, np.float32)
    pts = _as_tensor(np.ascontiguousarray(xyz, dtype=np.float32))
    project = _projector(cam, settings, torch.device("cpu"))
    box = np.array([left, top, left + fw, top + fh], np.int64)
    for start in range(0, int(pts.shape[0]), settings.chunk_points):
        valid, u, v, z = project(pts[start : start + settings.chunk_points])
        ui = torch.where(valid, u.floor(), -1.0).to(torch.int64).numpy()
        vi = torch.where(valid, v.floor(), -1.0).to(torch.int64).numpy()
        kernels.nearest_depths(ui, vi, z.to(torch.float32).numpy(), box, out)
    return out[np.isfinite(out)]


def _within_pixel(
    pts: torch.Tensor, keys: torch.Tensor, cam: Camera, settings: RenderParams, dev: torch.device
) -> torch.Tensor:
    """(2, H W) float32 where in its pixel the point of each z-buffer key falls (u, v from the pixel's
    corner, 0 to 1; 0.5 where no point): the same projection as the render."""
    hit = keys != EMPTY_KEY
    which = torch.nonzero(hit).squeeze(1)
    out = torch.full((2, int(keys.shape[0])), 0.5, dtype=torch.float32, device=dev)
    if len(which):
        _, u, v, _ = _projector(cam, settings, dev)(pts[(keys[which] & INDEX_MASK).to(pts.device)])
        out[0, which] = (u - u.floor()).to(torch.float32)
        out[1, which] = (v - v.floor()).to(torch.float32)
    return out


def _winners(zbuf: torch.Tensor, npix: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(index, depth) per pixel of a z-buffer, on its device: (H W,) int64 winning point, -1 where
    none, and (H W,) float32 the depth its key holds (NaN where none)."""
    keys = zbuf[:npix]
    hit = keys != EMPTY_KEY
    index = torch.where(hit, keys & INDEX_MASK, -1)
    depth = torch.where(hit, (keys >> 32).to(torch.int32).view(torch.float32), float("nan"))
    return index, depth


def _decode(
    index: torch.Tensor,
    depth: torch.Tensor,
    W: int,
    H: int,
    attributes: Mapping[str, np.ndarray | torch.Tensor],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(hit, depth, index, attributes) images of a render's winners (index (H W,) int64, -1 where
    none; depth (H W,) float32). Only hit pixels are gathered, with torch on the CPU: index_select /
    index_copy_ are several times faster than numpy fancy indexing for millions of pixels (at full
    scale most of the buffer may be empty)."""
    npix = W * H
    index_cpu, depth_cpu = index.cpu(), depth.cpu()
    hit_flat = index_cpu >= 0
    hit_pix = torch.nonzero(hit_flat).squeeze(1)
    winners = index_cpu[hit_pix]
    depth_flat = torch.where(hit_flat, depth_cpu, float("nan"))
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
    return hit, depth_flat.numpy().reshape(H, W), index_cpu.numpy().reshape(H, W), out_attrs


def _trimmed(
    index: torch.Tensor,
    depth: torch.Tensor,
    pts: torch.Tensor,
    spacing: torch.Tensor,
    centres: torch.Tensor,
    cam: Camera,
    settings: RenderParams,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The render's winners after the edge trim (siteline.render.edges.trim_edges), and per pixel the
    point whose splat reached a pixel the trim gave away (-1 elsewhere)."""
    spacing_px = torch.where(index >= 0, spacing[index.clamp(min=0)] * _focal(cam) / depth, 0.0)
    centre_uv = _within_pixel(pts, centres, cam, settings, index.device)
    out_index, out_depth, trimmed = trim_edges(
        index, depth, spacing_px, centres, centre_uv, cam.width, settings.splat_max_px, _focal(cam)
    )
    return out_index, out_depth, torch.where(trimmed, index, -1)


def _behind_sparse(
    index: torch.Tensor,
    depth: torch.Tensor,
    pts: torch.Tensor,
    spacing: torch.Tensor,
    cam: Camera,
    settings: RenderParams,
    sparse_of: np.ndarray | None,
) -> torch.Tensor:
    """(H W,) int64: per pixel whose winner lies behind a sparse surface's reach, the nearest of that
    surface's points there; -1 elsewhere. A point ``sparse_of`` looks at ((N,) uint8 or bool: in the
    first that many cell sizes of :data:`SPARSE_CELLS`; None: every point in all) whose own surface
    is sparser than its spacing says (siteline.render.splats.surface_spacing: a pole's samples a metre
    apart, a beam's side) is drawn a second time, into a z-buffer of its own, as a disk of
    :data:`SPARSE_REACH` of its own spacing across (up to MAX_SPLAT_PX): a winner
    :data:`BEHIND_SPACINGS` of that spacing farther than the disk's sample may show through the
    surface where it lies between its samples (the ground between a pole's)."""
    dev = index.device
    npix = cam.width * cam.height
    out = torch.full((npix,), -1, dtype=torch.int64, device=dev)
    spacing_np = spacing.cpu().numpy()
    looked = (
        np.full(len(spacing_np), len(SPARSE_CELLS), np.uint8) if sparse_of is None else np.asarray(sparse_of)
    )
    named = np.flatnonzero(looked)
    xyz_np, own = pts.cpu().numpy(), spacing_np[named]
    for k, cells in enumerate(SPARSE_CELLS):
        sub = np.flatnonzero(looked[named] > k)
        if len(sub):
            own[sub] = np.maximum(own[sub], surface_spacing(xyz_np, spacing_np, named[sub], cells))
    raised = own > spacing_np[named]
    sparse, own = named[raised], own[raised]
    if not len(sparse):
        return out
    which = torch.from_numpy(sparse).to(dev)
    zbuf = torch.full((npix + 1,), EMPTY_KEY, dtype=torch.int64, device=dev)
    wide = replace(
        settings, splat="world", splat_max_px=MAX_SPLAT_PX, point_size_px=1, splat_factor=SPARSE_REACH
    )
    own_depth = torch.empty(len(sparse), dtype=torch.float32, device=dev)
    own_t = torch.from_numpy(own).to(dev)
    _splat(pts[which], own_t, cam, wide, dev, zbuf, own_depth)
    near, _ = _winners(zbuf, npix)
    at = near.clamp(min=0)
    # from the sample's own depth, not its disk's rim
    behind = (near >= 0) & (index >= 0) & (depth > own_depth[at] + BEHIND_SPACINGS * own_t[at])
    return torch.where(behind, which[at], -1)


def _unsure_of(
    index: torch.Tensor, depth: torch.Tensor, reached: torch.Tensor, centres: torch.Tensor,
    points: tuple[torch.Tensor, torch.Tensor, np.ndarray | None], cam: Camera, settings: RenderParams,
) -> np.ndarray:  # fmt: skip
    """RenderResult.unsure_of: where the trim gave a pixel away (``reached``), the point whose splat
    reached it; else where the winner shows through a nearer surface's holes or (``sparse_surfaces``)
    lies behind a sparse surface's reach, that surface's nearest sample; -1 elsewhere. (H, W) int64.
    points: the render's (N, 3) points, their spacings and which may be of a sparse surface
    (:func:`_behind_sparse`)."""
    pts, spacing, sparse_of = points
    holes = see_through(index, depth, centres, spacing, _focal(cam), cam.width, settings.splat_max_px)
    if settings.sparse_surfaces:
        behind = _behind_sparse(index, depth, pts, spacing, cam, settings, sparse_of)
        holes = torch.where(holes >= 0, holes, behind)
    return torch.where(reached >= 0, reached, holes).cpu().numpy().reshape(cam.height, cam.width)


def render_points(
    xyz: np.ndarray | torch.Tensor,
    camera: Camera,
    settings: RenderParams | None = None,
    attributes: Mapping[str, np.ndarray | torch.Tensor] | None = None,
    device: str | torch.device = "cpu",
    spacing_m: np.ndarray | torch.Tensor | None = None,
    sparse_of: np.ndarray | None = None,
) -> RenderResult:
    """Render site-local points through ``camera`` at ``settings.scale``.

    xyz: (N, 3) float32, site-local metres. attributes: name -> (N,) or (N, C) arrays of any dtype
    (uint8 RGB, uint8 class, bool flags). spacing_m: (N,) each point's spacing in metres, which
    world splats need (a tile read gives it; :func:`siteline.render.splats.local_spacing` estimates
    it for a raw cloud). sparse_of: (N,) uint8 or bool, with ``settings.sparse_surfaces`` the points
    whose surface is looked at for being sparse, and in how many of :data:`SPARSE_CELLS`' cell sizes
    (None: every point, in all; a pair names its labelled points, its changed ones in all).
    Returns a :class:`RenderResult` at the scaled camera.
    """
    settings = settings or RenderParams()
    attributes = dict(attributes or {})
    n = _check_inputs(xyz, attributes, settings, spacing_m)
    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise RenderError("device 'cuda' was asked for but torch sees no CUDA device.")
    cam = camera.scaled(settings.scale)
    npix = cam.width * cam.height
    t0 = time.perf_counter()
    pts = _as_tensor(xyz)
    spacing = None if spacing_m is None or settings.splat != "world" else _as_tensor(spacing_m).to(dev)
    zbuf = torch.full((npix + 1,), EMPTY_KEY, dtype=torch.int64, device=dev)
    world = settings.splat == "world"
    depths = torch.empty(n, dtype=torch.float32, device=dev) if world else None
    trim = world and settings.trim_edges and spacing is not None
    centres = torch.full((npix + 1,), EMPTY_KEY, dtype=torch.int64, device=dev) if trim else None
    in_frustum = _splat(pts, spacing, cam, settings, dev, zbuf, depths, centres)
    index, depth = _winners(zbuf, npix)
    if depths is not None and n:  # the winners' own depth, not their splat's
        depth = torch.where(index >= 0, depths[index.clamp(min=0)], float("nan"))
    reached = torch.full((npix,), -1, dtype=torch.int64, device=dev)
    if trim and centres is not None and spacing is not None and n:
        index, depth, reached = _trimmed(index, depth, pts, spacing, centres[:npix], cam, settings)
    drawn = int((index >= 0).sum())
    filled = torch.zeros(npix, dtype=torch.bool, device=dev)
    if settings.fill_px:
        index, depth, filled = fill_gaps(index, depth, cam.width, cam.height, settings.fill_px, CPU_KERNELS)
    unsure_of = None
    if trim and centres is not None and spacing is not None:
        unsure_of = _unsure_of(
            index, depth, reached, centres[:npix], (pts, spacing, sparse_of), cam, settings
        )
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)
    t_splat = time.perf_counter() - t0
    hit, depth_img, index_img, out_attrs = _decode(index, depth, cam.width, cam.height, attributes)
    filled_img = filled.cpu().numpy().reshape(cam.height, cam.width)
    stats = {
        "points_read": n,
        "points_in_frustum": in_frustum,
        "coverage": float(hit.mean()) if hit.size else 0.0,
        "drawn": drawn / npix if npix else 0.0,
        "filled": float(filled_img.mean()) if filled_img.size else 0.0,
        "trimmed": int((reached >= 0).sum()) / npix if npix else 0.0,
        "seconds": time.perf_counter() - t0,
        "seconds_splat": t_splat,
        "width": cam.width,
        "height": cam.height,
    }
    return RenderResult(
        camera=cam,
        hit=hit,
        depth=depth_img,
        index=index_img,
        attributes=out_attrs,
        stats=stats,
        filled=filled_img,
        unsure_of=unsure_of,
    )
