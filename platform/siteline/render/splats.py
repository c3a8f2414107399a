"""How much of the image one point covers: fixed disks, or disks sized by the point's spacing in the
world seen from the camera (DESIGN.md §6).

A disk of diameter d pixels centred on the pixel a point falls in covers the pixels whose centres lie
within d / 2 of that pixel's centre: 1 is the point's own pixel, 2 a cross of 5, 3 the 3 x 3 block.
World splats take ``d = splat_factor x spacing_m x f / depth`` rounded up (siteline.records.params.render), clamped to the point
size and ``splat_max_px``: near points of a sparse cloud get wide disks, far or dense ones a pixel.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator

import numpy as np
import torch

from siteline.errors import RenderError
from siteline.records.params.render import RenderParams
from siteline.render import kernels


@functools.lru_cache(maxsize=128)
def disk_offsets(point_size_px: int) -> list[tuple[int, int]]:
    """Pixel offsets (du, dv) covered by a disk of diameter ``point_size_px`` centred on a pixel."""
    r = point_size_px / 2.0
    k = point_size_px // 2
    return [(du, dv) for dv in range(-k, k + 1) for du in range(-k, k + 1) if du * du + dv * dv <= r * r]


@functools.lru_cache(maxsize=128)
def disk(diameter_px: int) -> tuple[np.ndarray, np.ndarray]:
    """The disk of :func:`disk_offsets` as arrays: (M, 2) int64 offsets (du, dv) and (M,) float64 each
    offset's squared distance over the squared radius (0 at the centre, at most 1)."""
    arr = np.array(disk_offsets(diameter_px), dtype=np.int64).reshape(-1, 2)
    return arr, (arr**2).sum(axis=1) / (diameter_px / 2.0) ** 2


@functools.lru_cache(maxsize=8)
def _nested(max_diameter_px: int) -> tuple[np.ndarray, np.ndarray]:
    """The offsets of the widest disk sorted by distance from the centre, (M, 3) int64 (du, dv,
    du**2 + dv**2), so every smaller disk is a prefix of them; and (max + 1,) int64 the prefix
    length of each diameter."""
    offs = np.array(disk_offsets(max_diameter_px), dtype=np.int64).reshape(-1, 2)
    rho2 = (offs**2).sum(axis=1)
    order = np.lexsort((offs[:, 0], offs[:, 1], rho2))
    table = np.c_[offs[order], rho2[order]]
    lengths = np.array([int((4 * rho2 <= d * d).sum()) for d in range(max_diameter_px + 1)], dtype=np.int64)
    return table, lengths


def disk_pixels(
    diameters: torch.Tensor, max_diameter_px: int, budget: int = 4_000_000
) -> Iterator[tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]]:
    """Every pixel of every point's disk, as flat tensors ``(point, du, dv, rho2)``: the point's
    position in ``diameters`` ((M,) int64 pixels), the pixel's offset from the point's pixel and its
    squared distance (pixels**2); in groups of at most ``budget`` pixels, each point whole in one
    group (so memory stays bounded whatever the disks). All on ``diameters``' device."""
    dev = diameters.device
    table, lengths = _nested(max_diameter_px)
    offs = torch.as_tensor(table, device=dev)
    counts = torch.as_tensor(lengths, device=dev)[diameters.clamp(0, max_diameter_px)]
    ends = torch.cumsum(counts, 0)
    n = int(diameters.shape[0])
    start, done = 0, 0
    while start < n:
        stop = int(torch.searchsorted(ends, done + budget, right=True))
        stop = min(n, max(stop, start + 1))
        mine = counts[start:stop]
        total = int(ends[stop - 1]) - done
        point = torch.repeat_interleave(torch.arange(start, stop, device=dev), mine, output_size=total)
        first = torch.repeat_interleave(torch.cumsum(mine, 0) - mine, mine, output_size=total)
        k = torch.arange(total, device=dev) - first
        yield point, offs[k, 0], offs[k, 1], offs[k, 2]
        start, done = stop, done + total


def diameters_px(
    spacing_m: torch.Tensor | None, z: torch.Tensor, focal_px: float, settings: RenderParams
) -> torch.Tensor:
    """(M,) int64 splat diameter of each point in pixels: the point size for fixed splats; for world
    splats ``settings.splat_factor x spacing_m x focal_px / z`` rounded up, at least the point size and
    at most ``splat_max_px``. spacing_m, z: (M,) metres (points with z <= 0 or no finite value get
    the point size; they are not drawn anyway)."""
    lo, hi = settings.point_size_px, settings.splat_max_px
    if settings.splat == "fixed" or spacing_m is None:
        return torch.full(z.shape, lo, dtype=torch.int64, device=z.device)
    d = settings.splat_factor * focal_px * spacing_m.to(device=z.device, dtype=z.dtype) / z
    d = torch.where(z > 0, torch.nan_to_num(d, nan=0.0, posinf=float(hi)), 0.0)
    return d.clamp_(lo, hi).ceil_().to(torch.int64)


def check_spacing(spacing_m: np.ndarray | torch.Tensor | None, n: int, settings: RenderParams) -> None:
    """Refuse world splats without one spacing per point (metres, finite, positive)."""
    if settings.splat != "world":
        return
    if spacing_m is None:
        raise RenderError(
            "world splats need each point's spacing in metres (spacing_m): a tile read gives it "
            "(SceneTiles.points_for_view), siteline.render.splats.local_spacing estimates it for a raw cloud."
        )
    if tuple(spacing_m.shape) != (n,):
        raise RenderError(f"spacing_m has shape {tuple(spacing_m.shape)} for {n} points; give one per point.")


# a surface sparser than its level of detail says: a point whose cell of CELL_SPACINGS of its spacing
# s (rounded up to a power of two: 4-8 s; the larger count of two grids half a cell apart, so that no
# column straddles both grids' edges) holds fewer than a SPARSE_SHARE of the (edge / s)**2 points a
# surface at s puts there: its own spacing is more than twice s (a pole's column, a wall a flight
# grazed, a jib's side)
CELL_SPACINGS = 4.0
SPARSE_SHARE = 0.25
# such a point's own spacing: the distance to the farther of its two nearest sparse neighbours (points
# of cells up to twice as full count too; a column's sample: the farther of the samples above and
# below it), where that is at most FAR_SPACINGS of s; a sample with no sparse neighbour that near keeps
# s (nothing to bridge)
FAR_SPACINGS = 32.0


def surface_spacing(
    xyz: np.ndarray,
    spacing_m: np.ndarray,
    which: np.ndarray | None = None,
    cell_spacings: float = CELL_SPACINGS,
) -> np.ndarray:
    """(M,) float32 metres: the spacing ``spacing_m`` (N,) (its level of detail's, or its tile's) of
    each point ``which`` names ((M,) int64 positions; None: every point), raised where the point's own
    surface is sparser (see :data:`SPARSE_SHARE`) to the distance to the farther of its two nearest
    sparse neighbours: a pole's samples a metre apart get about a metre, where their tile's ground
    says 0.11 m. xyz: (N, 3) site-local metres of one read (a view's points, a tile's); its cells are
    counted over every point, cells of ``cell_spacings`` of a point's spacing (rounded up to a power
    of two; :data:`CELL_SPACINGS` unless given). Costs a compiled pass over the points
    (siteline.render.kernels) and a k-d tree of the named points of sparse cells alone: naming the
    few that matter (a pair's changed points) keeps both small."""
    from scipy.spatial import cKDTree

    which = np.arange(len(spacing_m)) if which is None else np.asarray(which, dtype=np.int64)
    s = np.asarray(spacing_m, dtype=np.float32)
    out = s[which]
    if not len(which):
        return out
    level = np.ceil(np.log2(cell_spacings / 2 * np.maximum(s, 1e-4))).astype(np.int64)
    expected = (np.exp2(level[which] + 1) / np.maximum(out, 1e-4)) ** 2  # a surface at the spacing
    cap = np.ceil(2 * SPARSE_SHARE * expected).astype(np.int64)  # counted exactly below (``around``)
    share = kernels.cell_counts(np.ascontiguousarray(xyz, dtype=np.float32), level, which, cap) / expected
    sparse = np.flatnonzero(share < SPARSE_SHARE)
    if not len(sparse):
        return out
    # their neighbours are looked for among the named points of cells up to twice as full: a column's
    # samples that happen to lie closer together are not sparse, but are still its neighbours
    pts = np.asarray(xyz)[which].astype(np.float64)
    around = pts[share < 2 * SPARSE_SHARE]
    if len(around) < 3:
        return out
    far = cKDTree(around).query(pts[sparse], k=3)[0][:, 2].astype(np.float32)
    near = far <= FAR_SPACINGS * out[sparse]
    out[sparse[near]] = np.maximum(out[sparse[near]], far[near])
    return out


def local_spacing(xyz: np.ndarray, neighbours: int = 8) -> np.ndarray:
    """(N,) float32 metres: each point's spacing, ``sqrt(pi / density)`` from the distance to its
    ``neighbours``-th nearest neighbour (density = neighbours / (pi d^2) on a surface), for a raw
    cloud with no level of detail. xyz: (N, 3) site-local metres. Costs a k-d tree of the cloud."""
    from scipy.spatial import cKDTree

    pts = np.asarray(xyz, dtype=np.float64)
    if len(pts) <= neighbours:
        return np.full(len(pts), np.inf if len(pts) < 2 else 1.0, dtype=np.float32)
    d, _ = cKDTree(pts).query(pts, k=neighbours + 1, workers=-1)
    # neighbours points within d on a surface: density k / (pi d^2), spacing 1 / sqrt(density)
    return (d[:, -1] * math.sqrt(math.pi / neighbours)).astype(np.float32)
