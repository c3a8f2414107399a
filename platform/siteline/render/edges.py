"""Edge trim: a world splat must not cover a farther surface beyond the edge of its own (DESIGN.md §6).

A world splat is a disk of its point's spacing times the splat factor, so at an object's silhouette it
reaches past where the surface ends and hides the farther surface behind (the ground around a
container, the sky-facing ground under a jib's edge). A drawn pixel is trimmed, given the farther
surface, when:

- no point of its winner's surface (a point no farther than :data:`TRIM_SAME_SPACINGS` of the
  winner's spacing beyond its depth) falls within :data:`KEEP_SPACINGS` of the winner's spacing of the
  pixel's centre (measured to where the point falls within its pixel, not to the pixel), how far a
  surface is taken to extend past its last sample;
- the points of that surface within :data:`REACH_SPACINGS` spacings leave a run of more than
  :data:`siteline.render.fill.MAX_EMPTY_SECTORS` of the eight 45-degree sectors around the pixel
  empty (a pixel beyond a straight edge has half of them empty; one inside a surface has none), and
  the pixel lies farther than :data:`KEEP_SPACINGS` from the segment joining the nearest samples of
  any two opposite sectors (a pole's or a beam's samples, one above and one below it);
- a point of a farther surface falls within that reach: the pixel takes the nearest such point (by
  pixel distance), its colour and labels.

Where no farther point is near, the splat stays (sky beyond a roof edge is ignore in every mask). Cost:
one extra one-pixel scatter per point and one pass over the pixels; it grows with pixels, not
points. Measured against analytic truth in docs/performance.md.

Both the trim and a sparse surface's holes can show a farther surface where the nearer one may lie
(within a point spacing of its edge, or between its samples): :func:`see_through` finds the holes,
and a pair's mask ignores such pixels where the two surfaces' change differs (siteline.pairs.render).
"""

from __future__ import annotations

import functools

import numpy as np
import torch

from siteline.render import kernels
from siteline.render.fill import SAME_SURFACE, enclosed_table, ring_offsets

# a surface is taken to extend this many of its spacings past its last sample: a quarter, measured
# against analytic truth (a half drew edges a pixel too far, docs/performance.md)
KEEP_SPACINGS = 0.25
# how far around a pixel (in its winner's spacings) its surface's samples are looked for
REACH_SPACINGS = 2.5
# a point belongs to a drawn pixel's surface when it lies no more than this many of the winner's
# spacings beyond it: within the reach a surface seen at 27 degrees or more recedes by at most 5.
# A tenth of the depth (SAME_SURFACE, before 2026-11-30) took the ground a metre behind a fence
# panel's foot, or beside a car, for the nearer surface and kept its splats over them (the sloped
# scene's changed-class precision 0.960 -> 0.975, docs/performance.md)
TRIM_SAME_SPACINGS = 5.0


@functools.lru_cache(maxsize=8)
def ring(radius_px: int) -> np.ndarray:
    """(M, 4) int64 rows (du, dv, squared distance, sector) of every offset within ``radius_px`` but
    the centre (the gap fill's offsets and sectors, siteline.render.fill.ring_offsets), nearest first
    (ties by row, then column)."""
    rows = [r for r in ring_offsets(radius_px) if r[2] <= radius_px * radius_px]
    rows.sort(key=lambda r: (r[2], r[1], r[0]))
    return np.array(rows, dtype=np.int64).reshape(-1, 4)


def _centres(centres: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The point index (-1 none) and depth (float32 metres, inf none) of each pixel's one-pixel centre,
    from the z-buffer keys (float32 depth bits << 32 | point index; int64 max where none)."""
    empty = centres == torch.iinfo(torch.int64).max
    index = torch.where(empty, -1, centres & 0xFFFFFFFF)
    depth = torch.where(empty, float("inf"), (centres >> 32).to(torch.int32).view(torch.float32))
    return index, depth.to(torch.float32)


def trim_edges(
    index: torch.Tensor,
    depth: torch.Tensor,
    spacing_px: torch.Tensor,
    centres: torch.Tensor,
    centre_uv: torch.Tensor,
    width: int,
    max_radius_px: int,
    focal_px: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Trim the splats of one render at their surfaces' edges (see the module docstring).

    index: (H W,) int64 winning point per pixel, -1 none; depth: (H W,) float32 metres, the winner's
    own camera depth; spacing_px: (H W,) float32 the winner's spacing in pixels; centres: (H W,) int64
    z-buffer keys of one-pixel points (float32 depth bits << 32 | point index; int64 max where none);
    centre_uv: (2, H W) float32 where in its pixel each of those points falls (0 to 1); max_radius_px:
    the widest reach looked at; focal_px: the render's focal length (pixels). Returns the new (index,
    depth) and (H W,) bool ``trimmed``, on the tensors' device (the pass itself runs compiled on the
    CPU: its cost is per pixel)."""
    dev = index.device
    centre_index, centre_depth = _centres(centres)
    centre = torch.cat([centre_depth[None], centre_uv.to(torch.float32)]).cpu().numpy()
    spx = torch.nan_to_num(spacing_px.to(torch.float32), nan=0.0, posinf=float(max_radius_px))
    drawn = torch.stack([depth.to(torch.float32), spx]).cpu().numpy().copy()
    out_index = index.cpu().numpy().copy()
    knobs = np.array([TRIM_SAME_SPACINGS / focal_px, KEEP_SPACINGS, REACH_SPACINGS], dtype=np.float32)
    done = kernels.trim_edges(
        out_index, drawn, centre_index.cpu().numpy(), np.ascontiguousarray(centre), ring(max(1, int(max_radius_px)) + 1),
        np.array(enclosed_table(), dtype=bool), knobs, width,
    )  # fmt: skip
    out_depth = drawn[0]
    return (
        torch.from_numpy(out_index).to(dev),
        torch.from_numpy(out_depth).to(dev),
        torch.from_numpy(done).to(dev),
    )


def see_through(
    index: torch.Tensor,
    depth: torch.Tensor,
    centres: torch.Tensor,
    spacing_m: torch.Tensor,
    focal_px: float,
    width: int,
    max_radius_px: int,
) -> torch.Tensor:
    """(H W,) int64: for each pixel whose winner lies behind a nearer surface's samples, which enclose
    it (one-pixel centres of points at least :data:`SAME_SURFACE` nearer than the winner, of one
    surface, within :data:`REACH_SPACINGS` of their spacing, leave no run of more than
    MAX_EMPTY_SECTORS of the eight sectors around it empty: the gap fill's test at the surface's own
    reach), that surface's nearest sample; -1 elsewhere. A sparse beam's splats leave holes wider
    than the gap fill closes; through them the ground is drawn where the beam is.

    index, depth: (H W,) the render's winners (after the gap fill) and their depths (metres);
    centres: (H W,) int64 z-buffer keys of one-pixel points (as :func:`trim_edges`); spacing_m: (N,)
    every point's spacing (metres); focal_px: the render's focal length; max_radius_px: the widest
    reach looked at."""
    centre_index, centre_depth = _centres(centres)
    spx = torch.where(
        centre_index < 0,
        0.0,
        spacing_m[centre_index.clamp(min=0)].to(torch.float32) * focal_px / centre_depth,
    )
    knobs = np.array([SAME_SURFACE, REACH_SPACINGS], dtype=np.float32)
    centre = torch.stack([centre_depth, torch.nan_to_num(spx, nan=0.0)]).cpu().numpy()
    found = kernels.see_through(
        index.cpu().numpy(), torch.nan_to_num(depth.to(torch.float32), nan=float("inf")).cpu().numpy(),
        centre_index.cpu().numpy(), np.ascontiguousarray(centre), ring(max(1, int(max_radius_px)) + 1),
        np.array(enclosed_table(), dtype=bool), knobs, width,
    )  # fmt: skip
    return torch.from_numpy(found).to(index.device)
