"""Cascade the strategies into candidate views, reject the unusable ones, draw a stratified sample."""

from __future__ import annotations

import hashlib
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from siteline.camera.pinhole import Camera
from siteline.errors import ViewsError
from siteline.progress import no_step
from siteline.records.pairs import ViewStrategy
from siteline.records.params.views import SAMPLER_VERSION, ViewParams
from siteline.render.zbuffer import central_depths, coverage_of
from siteline.schema import JSON, json_int, json_number, json_object, json_str
from siteline.site.fence import inside_fence
from siteline.tolerances import (
    LENGTH_TOL_M,
    POSE_CENTER_QUANTUM_M,
    POSE_ROTATION_QUANTUM,
    RATIO_TOL,
    at_least,
)
from siteline.views import strategies
from siteline.views.changes import ChangeSample, framed_pixels, shown_pixels
from siteline.views.ground import GroundChoice, GroundModel, GroundPlane
from siteline.views.sources import PointSource

# a view may draw at most this share of its surface from points farther apart than
# ViewParams.max_spacing_px (its nearest tenth, where nearer is sparser)
SPARSE_SHARE = 0.1
# the share is judged on at most this many of a probe's points (every k-th): a probe of a whole
# scene of a million points then costs ~5 ms more, not ~30
SPARSE_SAMPLE = 200_000
# a changed region short of views has at most this many of the candidates that frame it probed
# (nearest first is not asked: in key order, as the sample), so its cost is bounded per region
CHANGE_TRIES = 40


@dataclass(frozen=True)
class NamedCamera:
    """A real camera and the name of its image."""

    name: str
    camera: Camera


@dataclass(frozen=True)
class SyntheticView:
    """One synthetic view: its parent real camera, the strategy key, the parameters that made it, the
    camera (site-local), after rejection its probe's coverage at the render scale and the share of
    pixels its kept points cover (``probe_valid``: an upper bound of the view's valid share), or
    why it was rejected, once sampled its index in the pair's sample, and the pair's changed
    regions its probe shows at ``change_min_px`` or more (``shows``: numbers of the ChangeSample)."""

    parent: str
    strategy: str
    params: ViewStrategy
    camera: Camera
    coverage: float | None = None
    rejected: str | None = None
    index: int | None = None
    probe_valid: float | None = None
    shows: tuple[int, ...] = ()

    def to_dict(self) -> dict[str, JSON]:
        return {
            "index": self.index,
            "parent": self.parent,
            "strategy": self.strategy,
            "params": self.params.to_dict(),
            "coverage": self.coverage,
            "probe_valid": self.probe_valid,
            "camera": self.camera.to_dict(),
        }

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> SyntheticView:
        """From :meth:`to_dict`'s form; TypeError or KeyError where it is not one."""
        coverage, index, probe = doc.get("coverage"), doc.get("index"), doc.get("probe_valid")
        return cls(
            json_str(doc["parent"], "parent"),
            json_str(doc["strategy"], "strategy"),
            ViewStrategy.from_dict(json_object(doc["params"], "params")),
            Camera.from_dict(doc["camera"]),
            None if coverage is None else json_number(coverage, "coverage"),
            None,
            None if index is None else json_int(index, "index"),
            None if probe is None else json_number(probe, "probe_valid"),
        )


class Picker:
    """The stratified order (:func:`stratified_order`) of the candidates that pass ``judge``, worked
    out lazily: strata take turns in their hashed order, and on its turn a stratum's candidates are
    judged in key order until one passes. The sequence is exactly ``stratified_order`` of every
    passing candidate, but a candidate is judged (probed) only when its turn comes, so picking n
    views costs about n / (the share that passes) probes, whatever the candidates.

    ``judge`` returns the candidate with ``coverage`` and ``probe_valid`` set, and ``rejected`` when
    it fails; ``batch`` is told the candidates a turn of every stratum will judge first (a source
    may read them at once). ``rejected`` counts the verdicts so far, ``probed`` the candidates
    judged."""

    def __init__(
        self,
        views: Sequence[SyntheticView],
        seed: int,
        judge: Callable[[SyntheticView], SyntheticView],
        batch: Callable[[list[SyntheticView]], None] = lambda vs: None,
    ) -> None:
        pools = _strata(views, seed)
        self._pools = [pools[k] for k in sorted(pools, key=lambda k: (_key("siteline-stratum", seed, k), k))]
        self._at = [0] * len(self._pools)
        self._turn = 0
        self._judge = judge
        self._batch = batch
        self.rejected: Counter[str] = Counter()
        self.probed = 0

    def _next_of(self, k: int) -> SyntheticView | None:
        pool = self._pools[k]
        while self._at[k] < len(pool):
            v = self._judge(pool[self._at[k]])
            self._at[k] += 1
            self.probed += 1
            if v.rejected is None:
                return v
            self.rejected[v.rejected] += 1
        return None

    def next(self) -> SyntheticView | None:
        """The next passing candidate of the stratified order, or None when none is left."""
        while any(self._at[k] < len(p) for k, p in enumerate(self._pools)):
            k = self._turn
            if k == 0:  # a new round: the strata's next candidates, read together
                self._batch([p[a] for p, a in zip(self._pools, self._at, strict=True) if a < len(p)])
            self._turn = (k + 1) % len(self._pools)
            found = self._next_of(k)
            if found is not None:
                return found
        return None

    def take(self, n: int) -> list[SyntheticView]:
        """The next ``n`` passing candidates (fewer when the candidates run out)."""
        out: list[SyntheticView] = []
        while len(out) < n:
            v = self.next()
            if v is None:
                break
            out.append(v)
        return out


@dataclass
class ViewSet:
    """The outcome of view generation: the sample, the candidate count, what the cheap geometric
    tests rejected (``rejected``) and the picker that drew the sample (``reserve``: its next views
    replace views a later stage rejects, siteline.pairs: too few valid pixels); ``ground_choice``: how the ground was found and modelled, when the
    caller chose it (siteline.views.ground.model_ground); ``verdicts``: every probe's verdict so far,
    (parent, strategy) -> the judged view (the picker's, the reserve's and those probed for a change:
    each candidate probed once). With a pair's changes: ``unseen`` says why a region (a ChangeSample
    number) is in fewer views than asked."""

    views: list[SyntheticView]
    params: ViewParams
    ground: GroundModel
    candidates: int
    rejected: dict[str, int] = field(default_factory=dict)
    reserve: Picker | None = None
    ground_choice: GroundChoice | None = None
    unseen: dict[int, str] = field(default_factory=dict)
    verdicts: dict[tuple[str, str], SyntheticView] = field(default_factory=dict)

    def all_rejected(self) -> dict[str, int]:
        """Every rejection so far by reason: the geometric tests' and the probes'."""
        out = Counter(self.rejected)
        out.update(v.rejected for v in self.verdicts.values() if v.rejected)
        return dict(sorted(out.items()))

    @property
    def probed(self) -> int:
        """Candidates probed so far (the rest passed the geometric tests but were never needed)."""
        return len(self.verdicts)

    def next_reserve(self) -> SyntheticView | None:
        """The next view of the stratified order beyond those drawn (None when none is left); views
        added for a change are in the sample already and are passed over."""
        if self.reserve is None:
            return None
        sampled = {(v.parent, v.strategy) for v in self.views}
        while (v := self.reserve.next()) is not None:
            if (v.parent, v.strategy) not in sampled:
                return v
        return None

    def to_dict(self) -> dict[str, JSON]:
        return {
            "params": self.params.to_dict(),
            "sampler": SAMPLER_VERSION,
            ("ground_plane" if isinstance(self.ground, GroundPlane) else "terrain"): self.ground.to_dict(),
            "candidates": self.candidates,
            "probed": self.probed,
            "rejected": self.all_rejected(),
            "views": [v.to_dict() for v in self.views],
        }


def strategy_key(vertical_fraction: float, mirrored: bool, forward_fraction: float) -> str:
    return f"v{vertical_fraction:g}-{'mirror' if mirrored else 'orig'}-f{forward_fraction:g}"


def central_median_depth(camera: Camera, source: PointSource, params: ViewParams) -> float | None:
    """Median depth (metres) of the central image region, from a probe render of one-pixel points
    (the median needs depths, not closed surfaces); None if it is empty."""
    probe = source.points_for_view(camera, params.depth_probe_scale)
    d = central_depths(probe.xyz, camera, params.depth_probe_scale, params.central_fraction)
    return float(np.median(d)) if d.size else None


def candidate_views(
    parent: NamedCamera,
    ground: GroundModel,
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
                base = ViewStrategy(
                    vf, mirrored, ff, segment, params.mirror_rule if mirrored else None, depth
                )
                key = strategy_key(vf, mirrored, ff)
                if cam_m is None:
                    out.append(SyntheticView(parent.name, key, base, cam_v, rejected=reason))
                    continue
                if depth is None and ff > 0:
                    out.append(SyntheticView(parent.name, key, base, cam_m, rejected="nothing_ahead"))
                    continue
                step = ff * (depth or 0.0)
                out.append(
                    SyntheticView(
                        parent.name, key, replace(base, forward_m=step), strategies.forward(cam_m, step)
                    )
                )
    return out


def reject_geometric(
    views: list[SyntheticView],
    ground: GroundModel,
    fence_m: Sequence[Sequence[float]] | None,
    source: PointSource,
    params: ViewParams,
) -> list[SyntheticView]:
    """``views`` with ``rejected`` set on those underground, outside the fence after mirroring, within
    ``clearance_m`` of a point (of either scene of a pair, at full density: the source's
    ``nearest_within``) or under geometry (a coarse copy of the scene); views rejected before keep
    their reason.

    Each threshold is compared with the tolerances of :mod:`siteline.tolerances`: a view on the fence,
    or at exactly ``clearance_m`` or ``min_height_m`` is kept."""
    live = [v for v in views if v.rejected is None]
    if not live:
        return list(views)
    centers = np.array([v.camera.center for v in live])
    heights = ground.height(centers)
    near = source.nearest_within(centers, params.clearance_m)
    above = source.count_above(centers, params.overhead_radius_m)
    inside = inside_fence(centers[:, :2], fence_m) if fence_m is not None else np.ones(len(live), bool)
    judged: dict[int, SyntheticView] = {}
    for v, h, dist, up, ins in zip(live, heights, near, above, inside, strict=True):
        reason = (
            "underground" if not at_least(h, params.min_height_m, LENGTH_TOL_M)
            else "outside_fence" if v.params.mirrored and not ins
            else "near_surface" if not at_least(dist, params.clearance_m, LENGTH_TOL_M)
            else "under_geometry" if up > 0
            else None
        )  # fmt: skip
        if reason is not None:
            judged[id(v)] = replace(v, rejected=reason)
    return [judged.get(id(v), v) for v in views]


def sparse_share(
    xyz: np.ndarray, spacing_m: np.ndarray, camera: Camera, scale: float, max_spacing_px: float
) -> float:
    """The share of the surface a render of ``camera`` at ``scale`` draws that comes from points more
    than ``max_spacing_px`` pixels apart: each point in the frame weighted by the pixels its spacing
    spans there ((spacing x focal / depth)^2), hidden or not. ``xyz`` (N, 3) site-local metres,
    ``spacing_m`` (N,) the metres each point stands for; 0 when nothing is in the frame. A share, so
    a larger cloud is judged on every k-th point (at most :data:`SPARSE_SAMPLE` of them)."""
    step = max(1, -(-len(xyz) // SPARSE_SAMPLE))
    xyz, spacing_m = xyz[::step], spacing_m[::step]
    cam = camera.scaled(scale)
    uv, z = cam.project(xyz)
    on = cam.in_frame(uv, z)
    if not on.any():
        return 0.0
    px = np.asarray(spacing_m, np.float64)[on] * max(cam.fx, cam.fy) / z[on]
    area = px * px
    return float(area[px > max_spacing_px].sum() / area.sum())


def probe(
    view: SyntheticView, source: PointSource, params: ViewParams, changes: ChangeSample | None = None
) -> SyntheticView:
    """``view`` with its probe's ``coverage`` and ``probe_valid`` (the share of pixels kept points
    cover) at the render scale, ``rejected`` when under ``min_coverage`` or ``min_valid`` (exactly
    at a threshold passes: siteline.tolerances), or when more than :data:`SPARSE_SHARE` of the
    surface it shows is drawn from points more than ``max_spacing_px`` apart at the render scale
    (:func:`sparse_share`; a probe reads points about half a probe pixel apart where the data are
    denser, 2 render pixels at ``probe_factor`` 1/4, so spacings are exact from there up, and the
    bound is met below). A source without spacings (fixed splats) is not judged by spacing. With
    the pair's ``changes``, a view that passes says which regions it shows (``shows``:
    siteline.views.changes.shown_pixels at ``change_min_px`` or more)."""
    settings = params.probe_settings()
    points = source.points_for_view(view.camera, params.probe_scale)
    if points.spacing_m is None:
        settings = replace(settings, splat="fixed")
    cov = coverage_of(points.xyz, view.camera, settings, spacing_m=points.spacing_m, kept=points.kept)
    reason = (
        "low_coverage" if not at_least(cov.hit, params.min_coverage, RATIO_TOL)
        else "low_valid_probe" if not at_least(cov.kept, params.min_valid, RATIO_TOL)
        else None
    )  # fmt: skip
    if reason is None and points.spacing_m is not None and params.max_spacing_px > 0:
        sparse = sparse_share(points.xyz, points.spacing_m, view.camera, params.scale, params.max_spacing_px)
        reason = "sparse_points" if sparse > SPARSE_SHARE + RATIO_TOL else None
    shows: tuple[int, ...] = ()
    if reason is None and changes is not None and changes.count:
        px = shown_pixels(changes, points.xyz, view.camera, params.scale)
        shows = tuple(int(r) for r in np.flatnonzero(px >= params.change_min_px))
    return replace(view, coverage=cov.hit, probe_valid=cov.kept, rejected=reason, shows=shows)


def reject(
    views: list[SyntheticView],
    ground: GroundModel,
    fence_m: Sequence[Sequence[float]] | None,
    source: PointSource,
    params: ViewParams,
) -> list[SyntheticView]:
    """Every view judged: the geometric tests (:func:`reject_geometric`), then a probe of each that
    passes them (:func:`probe`)."""
    judged = reject_geometric(views, ground, fence_m, source, params)
    source.prefetch([v.camera for v in judged if v.rejected is None], params.probe_scale)
    return [probe(v, source, params) if v.rejected is None else v for v in judged]


def _key(*parts: object) -> int:
    digest = hashlib.sha256("\0".join(str(p) for p in parts).encode()).digest()
    return int.from_bytes(digest[:8], "big")


def candidate_key(seed: int, parent: str, strategy: str) -> int:
    """The sampling key of one candidate: a hash of the seed, its parent image and its strategy, so
    that a candidate's rank never depends on which other candidates survived rejection."""
    return _key("siteline-view", seed, parent, strategy)


def _strata(views: Sequence[SyntheticView], seed: int) -> dict[str, list[SyntheticView]]:
    """The views by strategy stratum, each stratum ranked by :func:`candidate_key`."""
    strata: dict[str, list[SyntheticView]] = defaultdict(list)
    for v in views:
        strata[v.strategy].append(v)
    return {
        k: sorted(vs, key=lambda v: (candidate_key(seed, v.parent, v.strategy), v.parent))
        for k, vs in strata.items()
    }


def stratified_order(views: Sequence[SyntheticView], seed: int) -> list[SyntheticView]:
    """Every view, round-robin over strategy strata: members of a stratum ranked by
    :func:`candidate_key`, strata by a hash of the seed and their name. Any prefix of it is a
    stratified sample; the views after a prefix are its replacements, in order."""
    pools = _strata(views, seed)
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


def _victim(views: list[SyntheticView], added: set[int], counts: np.ndarray, k: int) -> SyntheticView | None:
    """The last drawn view of the stratified sample that no region needs (each region it shows is in
    more than ``k`` views), or None."""
    for v in reversed(views):
        if id(v) not in added and all(counts[q] > k for q in v.shows):
            return v
    return None


def _why_unseen(
    rejected: Sequence[SyntheticView], tried: Sequence[SyntheticView], drawn: Sequence[SyntheticView] = ()
) -> str:
    """Why a region stays short of views: a candidate probed for it passed but does not show it, or a
    view already drawn frames it without showing it (``drawn``): hidden; every candidate that frames
    it was rejected (``rejected`` by the geometric tests, or ``tried`` by their probe: the most
    common reason); or none frames it (too small)."""
    if drawn or any(v.rejected is None for v in tried):
        return "hidden"
    reasons = Counter(v.rejected for v in (*tried, *rejected) if v.rejected)
    return f"only:{reasons.most_common(1)[0][0]}" if reasons else "too_small"


def cover_changes(
    drawn: list[SyntheticView],
    candidates: Sequence[SyntheticView],
    changes: ChangeSample,
    judge: Callable[[SyntheticView], SyntheticView],
    params: ViewParams,
    batch: Callable[[list[SyntheticView]], None] = lambda vs: None,
) -> tuple[list[SyntheticView], dict[int, str]]:
    """``drawn`` (the stratified sample, in the order drawn) with views added until each changed
    region is in ``change_views`` of them, where candidates show it, and why some are not.

    Regions are served largest first. A region short of views has the candidates not yet in the
    sample that frame it at ``change_min_px`` or more (siteline.views.changes.framed_pixels: its
    points in the frame, nothing in front considered) judged in candidate-key order (``judge``: the
    probe, which says what each passing view shows; at most :data:`CHANGE_TRIES` of them), and each
    that passes and shows it takes the place of the last drawn view that no region needs (the
    sample keeps its size; a sample short of ``views`` grows instead), until ``change_share`` of
    ``views`` were chosen so. ``candidates``: every
    candidate, those the geometric tests rejected with their reasons (they say why a region no
    passing candidate frames is unseen). Returns the views and, per region left short, why
    (``too_small``, ``outside_fence``, ``hidden``, ``view_budget``, or ``only:<rejection>`` when
    every candidate framing it was rejected: siteline.records.pairs.unseen_words)."""
    k = params.change_views
    views = list(drawn)
    counts = np.zeros(changes.count, np.int64)
    for v in views:
        counts[list(v.shows)] += 1
    if k <= 0 or not changes.count or (counts >= k).all():
        return views, {}
    pool = key_sorted(candidates, params.seed)
    framed = framed_pixels(changes, [v.camera for v in pool], params.scale) >= params.change_min_px
    taken = {(v.parent, v.strategy) for v in views}
    added: set[int] = set()
    most = int(params.change_share * params.views)
    unseen: dict[int, str] = {}
    for r in range(changes.count):
        if counts[r] >= k:
            continue
        if not changes.inside[r]:
            unseen[r] = "outside_fence"
            continue
        framing = [v for v, f in zip(pool, framed[:, r], strict=True) if f]
        live = [v for v in framing if v.rejected is None and (v.parent, v.strategy) not in taken][
            :CHANGE_TRIES
        ]
        if live and len(added) >= most:  # the views that may be chosen so are spent: nothing to probe
            unseen[r] = "view_budget"
            continue
        batch(live)
        tried = []
        for v in live:
            if counts[r] >= k:
                break
            j = judge(v)
            tried.append(j)
            if j.rejected is not None or r not in j.shows:
                continue
            if len(added) >= most:
                unseen[r] = "view_budget"
                break
            if len(views) >= params.views:
                victim = _victim(views, added, counts, k)
                if victim is None:
                    unseen[r] = "view_budget"
                    break
                views.remove(victim)
                counts[list(victim.shows)] -= 1
            views.append(j)
            added.add(id(j))
            taken.add((j.parent, j.strategy))
            counts[list(j.shows)] += 1
        if counts[r] < k and r not in unseen:
            unseen[r] = _why_unseen(
                [v for v in framing if v.rejected is not None],
                tried,
                [v for v in framing if v.rejected is None and (v.parent, v.strategy) in taken],
            )
    return views, {r: why for r, why in unseen.items() if counts[r] < k}


def generate_views(
    cameras: Iterable[NamedCamera],
    ground: GroundModel,
    fence_m: Sequence[Sequence[float]] | None,
    source: PointSource,
    params: ViewParams | None = None,
    progress: Callable[[int], None] = no_step,
    changes: ChangeSample | None = None,
) -> ViewSet:
    """Synthetic views of one scene (the later scene of a pair): candidates for every real camera,
    the geometric tests, then a seeded stratified sample of ``params.views`` of those that pass their
    probe (:class:`Picker`: probed in the sample's order until enough pass), indexed 0..n-1; with
    the pair's ``changes``, views added so that each changed region is seen (:func:`cover_changes`).
    ``progress`` gets 1 per real camera and per view drawn.

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
        candidates.extend(reject_geometric(cands, ground, fence_m, source, params))
        progress(1)
    survivors = [v for v in candidates if v.rejected is None]
    verdicts: dict[tuple[str, str], SyntheticView] = {}

    def judge(v: SyntheticView) -> SyntheticView:  # each candidate probed once, whoever asks
        key = (v.parent, v.strategy)
        if key not in verdicts:
            verdicts[key] = probe(v, source, params, changes)
        return verdicts[key]

    def prefetch(vs: list[SyntheticView]) -> None:
        source.prefetch([v.camera for v in vs], params.probe_scale)

    picker = Picker(survivors, params.seed, judge, prefetch)
    drawn = []
    for _ in range(params.views):
        v = picker.next()
        if v is None:
            break
        drawn.append(v)
        progress(1)
    unseen: dict[int, str] = {}
    if changes is not None:
        drawn, unseen = cover_changes(drawn, candidates, changes, judge, params, prefetch)
    sample = [replace(v, index=i) for i, v in enumerate(key_sorted(drawn, params.seed))]
    rejected = dict(sorted(Counter(v.rejected for v in candidates if v.rejected).items()))
    return ViewSet(
        sample, params, ground, len(candidates), rejected, picker, unseen=unseen, verdicts=verdicts
    )
