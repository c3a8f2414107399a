"""Cascade the strategies into candidate views, reject the unusable ones, draw a stratified sample."""

from __future__ import annotations

import hashlib
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from siteline.cameras import Camera
from siteline.errors import ViewsError
from siteline.fence import inside_fence
from siteline.progress import no_step
from siteline.render.settings import RenderSettings
from siteline.render.zbuffer import coverage_of, render_points
from siteline.tolerances import (
    LENGTH_TOL_M,
    POSE_CENTER_QUANTUM_M,
    POSE_ROTATION_QUANTUM,
    RATIO_TOL,
    at_least,
)
from siteline.views import strategies
from siteline.views.ground import GroundPlane
from siteline.views.params import SAMPLER_VERSION, ViewParams
from siteline.views.sources import PointSource


@dataclass(frozen=True)
class NamedCamera:
    """A real camera and the name of its image."""

    name: str
    camera: Camera


@dataclass(frozen=True)
class SyntheticView:
    """One synthetic view: its parent real camera, the strategy key, the parameters that made it, the
    camera (site-local), after rejection its coverage at the render scale (or why it was rejected),
    and once sampled its index in the pair's sample."""

    parent: str
    strategy: str
    params: dict[str, Any]
    camera: Camera
    coverage: float | None = None
    rejected: str | None = None
    index: int | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "parent": self.parent,
            "strategy": self.strategy,
            "params": self.params,
            "coverage": self.coverage,
            "camera": self.camera.to_dict(),
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> SyntheticView:
        return cls(
            doc["parent"],
            doc["strategy"],
            doc["params"],
            Camera.from_dict(doc["camera"]),
            doc.get("coverage"),
            None,
            doc.get("index"),
        )


@dataclass
class ViewSet:
    """The outcome of view generation: the sample, and counts of what was generated and rejected."""

    views: list[SyntheticView]
    params: ViewParams
    ground: GroundPlane
    candidates: int
    rejected: dict[str, int] = field(default_factory=dict)
    # kept candidates beyond the sample, in stratified order: replacements for views a later stage
    # rejects (siteline.pairs: too few valid pixels)
    reserve: list[SyntheticView] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "params": self.params.to_dict(),
            "sampler": SAMPLER_VERSION,
            "ground_plane": self.ground.to_dict(),
            "candidates": self.candidates,
            "rejected": self.rejected,
            "views": [v.to_dict() for v in self.views],
        }


def strategy_key(vertical_fraction: float, mirrored: bool, forward_fraction: float) -> str:
    return f"v{vertical_fraction:g}-{'mirror' if mirrored else 'orig'}-f{forward_fraction:g}"


def central_median_depth(camera: Camera, source: PointSource, params: ViewParams) -> float | None:
    """Median depth (metres) of the central image region, from a probe render; None if it is empty."""
    r = render_points(
        source.points_for_view(camera, params.depth_probe_scale),
        camera,
        RenderSettings(scale=params.depth_probe_scale, point_size_px=params.point_size_px),
    )
    H, W = r.hit.shape
    fh, fw = max(1, int(round(H * params.central_fraction))), max(1, int(round(W * params.central_fraction)))
    top, left = (H - fh) // 2, (W - fw) // 2
    d = r.depth[top : top + fh, left : left + fw]
    d = d[np.isfinite(d)]
    return float(np.median(d)) if d.size else None


def candidate_views(
    parent: NamedCamera,
    ground: GroundPlane,
    fence_m: Sequence[Sequence[float]] | None,
    depth_of: Callable[[Camera], float | None],
    params: ViewParams,
) -> list[SyntheticView]:
    """All ``params.per_camera`` candidates of one real camera, cascaded vertical -> mirror -> forward.

    A candidate that cannot exist (no fence to mirror across, nothing ahead to step towards) is
    returned with ``rejected`` set, so the count is always ``per_camera``.
    """
    out: list[SyntheticView] = []
    for vf in params.vertical_fractions:
        cam_v = strategies.vertical(parent.camera, ground, vf)
        for mirrored in (False, True) if params.mirror else (False,):
            segment = None
            cam_m: Camera | None = cam_v
            reason = None
            if mirrored:
                if fence_m is None:
                    cam_m, reason = None, "no_fence"
                else:
                    cam_m, segment = strategies.mirror(cam_v, fence_m, ground, params.mirror_rule)
            depth = depth_of(cam_m) if cam_m is not None else None
            for ff in params.forward_fractions:
                base = {
                    "vertical_fraction": vf,
                    "mirrored": mirrored,
                    "forward_fraction": ff,
                    "mirror_segment_m": segment,
                    "mirror_rule": params.mirror_rule if mirrored else None,
                    "central_depth_m": depth,
                }
                key = strategy_key(vf, mirrored, ff)
                if cam_m is None:
                    out.append(
                        SyntheticView(parent.name, key, base | {"forward_m": None}, cam_v, rejected=reason)
                    )
                    continue
                if depth is None and ff > 0:
                    out.append(
                        SyntheticView(
                            parent.name, key, base | {"forward_m": None}, cam_m, rejected="nothing_ahead"
                        )
                    )
                    continue
                step = ff * (depth or 0.0)
                out.append(
                    SyntheticView(
                        parent.name, key, base | {"forward_m": step}, strategies.forward(cam_m, step)
                    )
                )
    return out


def reject(
    views: list[SyntheticView],
    ground: GroundPlane,
    fence_m: Sequence[Sequence[float]] | None,
    source: PointSource,
    params: ViewParams,
) -> list[SyntheticView]:
    """``views`` with ``rejected`` set on those underground, outside the fence after mirroring, within
    ``clearance_m`` of a surface, under geometry, or below ``min_coverage``, and ``coverage`` on the
    rest (views rejected before keep their reason).

    Each threshold is compared with the tolerances of :mod:`siteline.tolerances`: a view on the fence,
    at exactly ``clearance_m`` or ``min_height_m``, or at exactly ``min_coverage`` is kept."""
    live = [v for v in views if v.rejected is None]
    if not live:
        return list(views)
    centers = np.array([v.camera.center for v in live])
    heights = ground.height(centers)
    near = source.nearest_distance(centers)
    above = source.count_above(centers, params.overhead_radius_m)
    inside = inside_fence(centers[:, :2], fence_m) if fence_m is not None else np.ones(len(live), bool)
    settings = RenderSettings(scale=params.scale, point_size_px=params.point_size_px)
    judged: dict[int, SyntheticView] = {}
    probed = []
    for v, h, dist, up, ins in zip(live, heights, near, above, inside, strict=True):
        reason = (
            "underground" if not at_least(h, params.min_height_m, LENGTH_TOL_M)
            else "outside_fence" if v.params["mirrored"] and not ins
            else "near_surface" if not at_least(dist, params.clearance_m, LENGTH_TOL_M)
            else "under_geometry" if up > 0
            else None
        )  # fmt: skip
        if reason is not None:
            judged[id(v)] = replace(v, rejected=reason)
        else:
            probed.append(v)
    source.prefetch([v.camera for v in probed], params.scale)  # the probes that pass the cheap tests
    for v in probed:
        coverage = coverage_of(source.points_for_view(v.camera, params.scale), v.camera, settings)
        low = not at_least(coverage, params.min_coverage, RATIO_TOL)
        judged[id(v)] = replace(v, coverage=coverage, rejected="low_coverage" if low else None)
    return [judged.get(id(v), v) for v in views]


def _key(*parts: object) -> int:
    digest = hashlib.sha256("\0".join(str(p) for p in parts).encode()).digest()
    return int.from_bytes(digest[:8], "big")


def candidate_key(seed: int, parent: str, strategy: str) -> int:
    """The sampling key of one candidate: a hash of the seed, its parent image and its strategy, so
    that a candidate's rank never depends on which other candidates survived rejection."""
    return _key("siteline-view", seed, parent, strategy)


def stratified_order(views: Sequence[SyntheticView], seed: int) -> list[SyntheticView]:
    """Every view, round-robin over strategy strata: members of a stratum ranked by
    :func:`candidate_key`, strata by a hash of the seed and their name. Any prefix of it is a
    stratified sample; the views after a prefix are its replacements, in order."""
    strata: dict[str, list[SyntheticView]] = defaultdict(list)
    for v in views:
        strata[v.strategy].append(v)
    pools = {
        k: sorted(vs, key=lambda v: (candidate_key(seed, v.parent, v.strategy), v.parent))
        for k, vs in strata.items()
    }
    key_order = sorted(pools, key=lambda k: (_key("siteline-stratum", seed, k), k))
    order: list[SyntheticView] = []
    depth = 0
    while any(len(pools[k]) > depth for k in key_order):
        order.extend(pools[k][depth] for k in key_order if len(pools[k]) > depth)
        depth += 1
    return order


def key_sorted(views: Sequence[SyntheticView], seed: int) -> list[SyntheticView]:
    """``views`` in candidate-key order (the order of a sample, which does not depend on the pool)."""
    return sorted(views, key=lambda v: (candidate_key(seed, v.parent, v.strategy), v.parent, v.strategy))


def stratified_sample(views: Sequence[SyntheticView], n: int, seed: int) -> list[SyntheticView]:
    """Draw ``n`` views (all if fewer), round-robin over strategy strata, so stratum counts differ by
    at most one wherever strata have views to give (the first ``n`` of :func:`stratified_order`).

    Removing one candidate from the pool changes at most one chosen view (the removed one is
    replaced by the next of its stratum, or by one more of another stratum). The sample is returned
    in key order, so its order does not depend on the pool either.
    """
    return key_sorted(stratified_order(views, seed)[:n], seed)


def generate_views(
    cameras: Iterable[NamedCamera],
    ground: GroundPlane,
    fence_m: Sequence[Sequence[float]] | None,
    source: PointSource,
    params: ViewParams | None = None,
    progress: Callable[[int], None] = no_step,
) -> ViewSet:
    """Synthetic views of one scene (the later scene of a pair): candidates for every real camera,
    rejection, then a seeded stratified sample of ``params.views``, indexed 0..n-1.

    Real camera poses are snapped first (siteline.tolerances), so the same site at any coordinate
    magnitude gives bit-identical views."""
    params = params or ViewParams()
    cams = [
        NamedCamera(c.name, c.camera.snapped(POSE_CENTER_QUANTUM_M, POSE_ROTATION_QUANTUM)) for c in cameras
    ]
    if not cams:
        raise ViewsError("no real cameras to generate views from.")

    def depth_of(cam: Camera) -> float | None:
        return central_median_depth(cam, source, params)

    candidates: list[SyntheticView] = []
    for parent in cams:
        cands = candidate_views(parent, ground, fence_m, depth_of, params)
        candidates.extend(reject(cands, ground, fence_m, source, params))
        progress(1)
    kept = [v for v in candidates if v.rejected is None]
    order = stratified_order(kept, params.seed)
    sample = [replace(v, index=i) for i, v in enumerate(key_sorted(order[: params.views], params.seed))]
    rejected = dict(sorted(Counter(v.rejected for v in candidates if v.rejected).items()))
    return ViewSet(sample, params, ground, len(candidates), rejected, order[params.views :])
