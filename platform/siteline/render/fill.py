"""Screen-space gap fill: pixels between the points of one surface get that surface's nearest point
(DESIGN.md §6).

A pixel is filled when no point reached it (a gap), or when a farther surface shows through where the
front surface's splats left a hole (see-through), and in both cases the front surface lies around it
on every side: among the pixels within ``radius_px``, those of the front surface (depth within
:data:`SAME_SURFACE` of the nearest one there) leave no run of more than :data:`MAX_EMPTY_SECTORS` of
the eight 45-degree sectors around it empty. A pixel beyond a surface's edge has half the sectors
empty and is never filled, so a region with no surface (sky, the unscanned, the far side of an
object) stays empty. A filled pixel takes the winning point of its nearest front-surface neighbour
(ties: the lower pixel number), so its colour and labels come from that point.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import torch

from siteline.render import kernels
from siteline.render.splats import disk

SECTORS = 8
# the longest run of empty 45-degree sectors a filled pixel may have around it: 2 (90 degrees); a
# pixel just outside a straight edge has 3 or more
MAX_EMPTY_SECTORS = 2
# neighbours within this share of the nearest neighbour's depth belong to the front surface; a
# pixel this much farther than the front surface around it is seen through that surface's gaps
SAME_SURFACE = 0.1
_NONE = torch.iinfo(torch.int64).max


@functools.lru_cache(maxsize=1)
def enclosed_table() -> list[bool]:
    """For each 8-bit set of occupied sectors: whether its longest cyclic run of empty sectors is at
    most :data:`MAX_EMPTY_SECTORS`."""
    table = []
    for bits in range(1 << SECTORS):
        longest = run = 0
        for k in range(2 * SECTORS):  # twice round: runs that wrap
            run = run + 1 if not bits >> (k % SECTORS) & 1 else 0
            longest = max(longest, min(run, SECTORS))
        table.append(longest <= MAX_EMPTY_SECTORS)
    return table


@functools.lru_cache(maxsize=16)
def ring_offsets(radius_px: int) -> list[tuple[int, int, int, int]]:
    """(du, dv, squared distance, sector) of every offset within ``radius_px`` but the centre."""
    offs, _ = disk(2 * radius_px + 1)
    out = []
    for du, dv in offs.tolist():
        if du == 0 and dv == 0:
            continue
        sector = int(math.floor((math.atan2(dv, du) + math.pi / SECTORS) / (2 * math.pi / SECTORS))) % SECTORS
        out.append((du, dv, du * du + dv * dv, sector))
    return out


def _square_max(x: torch.Tensor, radius_px: int) -> torch.Tensor:
    """The maximum of (1, 1, H, W) ``x`` over the (2 r + 1) square around each pixel, as a row pass
    and a column pass (2 (2 r + 1) comparisons a pixel, not (2 r + 1)**2)."""
    k = 2 * radius_px + 1
    rows = torch.nn.functional.max_pool2d(x, (1, k), stride=1, padding=(0, radius_px))
    return torch.nn.functional.max_pool2d(rows, (k, 1), stride=1, padding=(radius_px, 0))


def fill_gaps(
    index: torch.Tensor, depth: torch.Tensor, width: int, height: int, radius_px: int, compiled: bool = True
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Fill the gaps of one render (see the module docstring).

    index: (H W,) int64 winning point per pixel, -1 where none; depth: (H W,) float32 metres, the
    winner's camera depth (ignored where no winner). Returns the new (index, depth) and (H W,) bool
    ``filled``, the pixels that took a neighbour's point. Deterministic, on the tensors' device (on
    the CPU by a compiled loop unless ``compiled`` is False: the same pixels)."""
    dev = index.device
    hit = index >= 0
    filled = torch.zeros_like(hit)
    if radius_px < 1 or not bool(hit.any()):
        return index, depth, filled
    if dev.type == "cpu" and compiled:  # one compiled pass (siteline.render.kernels), the same pixels
        index, depth = index.clone(), depth.clone().to(torch.float32)
        ring = torch.tensor(ring_offsets(radius_px), dtype=torch.int64).numpy()
        table = np.array(enclosed_table(), dtype=bool)
        done = kernels.fill_gaps(
            index.numpy(), depth.numpy(), ring, table, np.float32(SAME_SURFACE), radius_px, width
        )
        return index, depth, torch.from_numpy(done)
    inf = torch.tensor(float("inf"), dtype=torch.float32, device=dev)
    z = torch.where(hit, depth.to(torch.float32), inf).view(1, 1, height, width)
    near = -_square_max(-z, radius_px)
    around = _square_max(hit.view(1, 1, height, width).to(torch.float32), radius_px)
    zf = z.view(-1)
    seen_through = hit & (zf > near.view(-1) * (1 + SAME_SURFACE))
    cand = torch.nonzero((~hit & (around.view(-1) > 0)) | seen_through).squeeze(1)
    if not len(cand):
        return index, depth, filled
    cv, cu = cand // width, cand % width
    neighbours = []
    front = torch.full(cand.shape, float("inf"), dtype=torch.float32, device=dev)
    for du, dv, d2, sector in ring_offsets(radius_px):
        u, v = cu + du, cv + dv
        inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
        q = torch.where(inside, v * width + u, 0)
        nz = torch.where(inside, zf[q], inf)
        front = torch.minimum(front, nz)
        neighbours.append((q, inside, nz, d2, sector))
    limit = front * (1 + SAME_SURFACE)
    bits = torch.zeros(cand.shape, dtype=torch.int64, device=dev)
    best = torch.full(cand.shape, _NONE, dtype=torch.int64, device=dev)
    for q, inside, nz, d2, sector in neighbours:
        on_front = inside & (nz <= limit)
        # beyond the image counts as empty: a surface must surround a pixel within the image
        bits |= on_front.to(torch.int64) << sector
        best = torch.minimum(best, torch.where(on_front, (d2 << 32) | q, _NONE))
    enclosed = torch.tensor(enclosed_table(), dtype=torch.bool, device=dev)[bits]
    behind = ~hit[cand] | (zf[cand] > limit)  # a gap, or a farther surface seen through one
    take = enclosed & behind & (best != _NONE)
    dst, src = cand[take], best[take] & 0xFFFFFFFF
    index = index.clone()
    depth = depth.clone()
    index[dst] = index[src]
    depth[dst] = depth[src]
    filled[dst] = True
    return index, depth, filled
