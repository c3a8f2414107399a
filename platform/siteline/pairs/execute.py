"""Processing a pair from its plan (the execute part; never touches the catalog): 3D change both ways,
synthetic views from the later scene, and every view rendered on both scenes with its symmetric mask
(DESIGN.md §4-§6). Outputs are published whole under the plan's address; outputs already there (same
parameters, label sets and tilings) are found with ``siteline.pairs.outputs.find_outputs``."""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from siteline.errors import PairError, ViewsError
from siteline.labels.change import Matching
from siteline.labels.regions import RegionRule
from siteline.labels.store import auto_radius, write_labels
from siteline.labelsets.store import open_labelled
from siteline.pairs.outputs import output_of
from siteline.pairs.plan import PairPlan
from siteline.pairs.regions import PairChanges, pair_changes
from siteline.pairs.render import LabelledPair, render_pair_view
from siteline.pairs.sources import TilePointSource
from siteline.progress import Progress, no_progress
from siteline.records.pairs import (
    ChangedRegion,
    ChangeLabels,
    ChangesSeen,
    PairOutput,
    PairSummary,
    RenderedView,
)
from siteline.records.params.labels import expected_false_change
from siteline.render.outputs import png_bytes
from siteline.render.threads import CpuThreads
from siteline.stores import Store, layout, move
from siteline.tiles.reader import SceneTiles
from siteline.tolerances import RATIO_TOL, at_least
from siteline.views.generate import NamedCamera, SyntheticView, ViewSet, generate_views, key_sorted
from siteline.views.ground import GroundChoice, GroundModel, model_ground

log = logging.getLogger(__name__)
FOLDERS = ("A", "B", "label")


def pair_labels(
    plan: PairPlan, t1: SceneTiles, t2: SceneTiles, store: Store, progress: Progress
) -> ChangeLabels:
    """The pair's change labels at its radius (given, or ``radius_multiplier`` x the sparser scene's
    median spacing), reused from the store when they are there, else computed and published."""
    label_params = plan.params.label_params()
    auto, info = auto_radius(t1, t2, label_params.radius_multiplier)
    radius = auto
    if label_params.radius_m is not None:
        radius = label_params.radius_m
        info = replace(info, given=True, multiplier=radius / (auto / label_params.radius_multiplier))
    # what the chosen radius costs on unchanged surfaces, recorded with the labels (and the lineage)
    info = replace(info, expected_false_change=expected_false_change(info.multiplier))
    uri = layout.pair_labels(
        store,
        plan.pair_id,
        plan.versions,
        radius,
        plan.change_rule.rule,
        label_params,
    )
    if store.is_complete(uri):  # made by an earlier run (one killed before its record, say)
        labels = ChangeLabels.from_dict(dict(store.open_group(uri).attrs) | {"uri": uri})
    else:
        progress("labels", 0, None)
        taxonomy = plan.site.taxonomy
        with store.publish(uri) as work:
            labels = write_labels(
                t1, t2, radius, taxonomy.ignored_lut(), work, geometric=plan.change_rule.geometric_lut(taxonomy),
                matching=Matching(surface=label_params.surface_test(radius), ground=plan.change_rule.ground_lut(taxonomy)),
                regions=RegionRule(label_params.min_region_points, label_params.sparse_regions),
            )  # fmt: skip
    log.info("pair %d: change labels at r = %.3f m (%s)", plan.pair_id, radius, uri)
    return replace(labels, uri=uri, radius=info)


def scene_ground(plan: PairPlan, t2: SceneTiles) -> GroundChoice:
    """The ground the later scene's views stand on (siteline.views.ground.model_ground): its ground
    class, or ground found from geometry where the class is missing or says nothing; a plane, or a
    terrain where the ground is not one. Read at 0.5 m, so its cost grows with the site's area, not
    its points. :class:`PairError` naming the scene when no ground is found at all."""
    taxonomy = plan.site.taxonomy
    read = t2.points(resolution=0.5, attributes=("class",))
    on_ground = read.attributes["class"] == taxonomy.id_of("ground")
    try:
        choice = model_ground(read.xyz_m, on_ground, seed=plan.params.seed)
    except ViewsError as exc:
        raise PairError(
            f"pair {plan.pair_id}: views are placed above the ground of the later scene {plan.t2.id}, and none "
            f"was found: {exc} Its cloud has {int(on_ground.sum())} ground-class points of {len(on_ground):,} read "
            "and no ground shape either. Check the scene's points (siteline scene show), or classify its ground "
            "(siteline scene export, then labels import with ground marked) and build again."
        ) from exc
    if choice.source != "class":
        log.info(
            "pair %d: scene %d has %d ground-class points of %s read; ground found from geometry (%d points, %.0f %%)",
            plan.pair_id, plan.t2.id, int(on_ground.sum()), f"{len(on_ground):,}", choice.ground_points, 100 * choice.share,
        )  # fmt: skip
    return choice


def pair_views(
    plan: PairPlan,
    t1: SceneTiles,
    t2: SceneTiles,
    progress: Progress,
    threads: CpuThreads | None = None,
    changes: PairChanges | None = None,
) -> ViewSet:
    """Synthetic views of the later scene (DESIGN.md §5): probes read its tiles at the pair's point
    size, no camera within the clearance of a point of either scene, each of the pair's changed
    regions (``changes``) in ``change_views`` views where candidates show it, torch's threads
    following the machine's load (``threads``; a new one when None);
    :class:`PairError` when it has no cameras or every candidate is rejected."""
    threads = threads or CpuThreads()
    if not plan.cameras:
        raise PairError(
            f"pair {plan.pair_id}: the later scene {plan.t2.id} has no cameras to derive views from "
            f"(ingested before cameras were planned for missions without photos); ingest its mission "
            f"again into a new site, or with photos."
        )
    params, taxonomy = plan.params, plan.site.taxonomy
    choice = scene_ground(plan, t2)
    names = {c.name for c in taxonomy.classes}
    skip = np.array([taxonomy.id_of(c) for c in ("snow", "noise") if c in names], dtype=np.uint8)
    source = TilePointSource(
        t2,
        skip,
        taxonomy.ignored_ids(),
        (t1,),
        lod_factor=params.lod_factor,
        point_size_px=params.point_size_px,
    )
    cams = [NamedCamera(n, c) for n, c in plan.cameras]

    def step(k: int) -> None:
        threads()
        progress("views", k, len(cams) + params.views)

    views = generate_views(
        cams,
        choice.model,
        plan.fence,
        source,
        params.view_params_spec(),
        progress=step,
        changes=changes.sample if changes is not None else None,
    )
    views.ground_choice = choice
    if not views.views:
        raise PairError(
            f"pair {plan.pair_id}: every synthetic view was rejected ({views.all_rejected()}); lower "
            "--min-coverage or --min-valid, or check the cameras."
        )
    log.info(
        "pair %d: %d views of %d candidates, %d probed (%d reads, %s points read, %s)",
        plan.pair_id, len(views.views), views.candidates, views.probed, source.reads, f"{source.points_read:,}",
        "the scene held in memory" if source.in_memory else "read per batch of probes",
    )  # fmt: skip
    return views


def look_tour(views: Sequence[SyntheticView], ground: GroundModel) -> list[SyntheticView]:
    """``views`` in the order a pair renders them: a greedy tour from the first, each next the view
    that looks nearest (the site-local point where its optical axis meets ``ground``; its camera's
    place where it looks level or up). Consecutive renders then read the same tiles, which the
    readers' chunk caches hold: at 8,000 points/m2 a 236-view pair renders in 0.81x the time of the
    sampled order (docs/performance.md). What a pair makes does not depend on the order (its views
    are indexed in key order, and a view replaced for too few valid pixels is replaced whatever its
    place)."""
    if len(views) < 3:
        return list(views)
    at = np.array([
        hit if (hit := ground.axis_hit(v.camera.center, v.camera.forward)) is not None else v.camera.center
        for v in views
    ])  # fmt: skip
    left = np.ones(len(views), bool)
    order = [0]
    left[0] = False
    for _ in range(len(views) - 1):
        gap = at - at[order[-1]]
        d = np.where(left, np.einsum("ij,ij->i", gap, gap), np.inf)
        order.append(int(np.argmin(d)))
        left[order[-1]] = False
    return [views[i] for i in order]


def _render_all(
    plan: PairPlan, scenes: LabelledPair, views: ViewSet, work: Path, device: str, progress: Progress
) -> tuple[list[tuple[SyntheticView, RenderedView]], dict[str, int]]:
    """Render the sample into ``work``/A|B|label under temporary names, torch's CPU threads following
    the machine's load; a view whose valid fraction is under ``min_valid`` is dropped and the next
    view of the stratified order rendered instead."""
    threads = CpuThreads(device)
    try:
        return _render_queue(plan, scenes, views, work, device, progress, threads)
    finally:
        threads.restore()


def _render_queue(
    plan: PairPlan,
    scenes: LabelledPair,
    views: ViewSet,
    work: Path,
    device: str,
    progress: Progress,
    threads: CpuThreads,
) -> tuple[list[tuple[SyntheticView, RenderedView]], dict[str, int]]:
    params = plan.params
    queue = look_tour(views.views, views.ground)
    low_valid = 0
    kept: list[tuple[SyntheticView, RenderedView]] = []
    for sub in FOLDERS:
        (work / sub).mkdir(parents=True)
    while queue:
        v = queue.pop(0)
        threads()
        r = render_pair_view(scenes, v.camera, params, device, plan.colour, plan.site.fence, views.ground)
        low = not at_least(r.valid, params.min_valid, RATIO_TOL)
        if low:
            low_valid += 1
            replacement = views.next_reserve()
            if replacement is not None:
                queue.append(replacement)
        # the total grows by each replacement
        progress("renders", 1, len(kept) + len(queue) + low_valid + (not low))
        if low:
            continue
        tmp = f"tmp-{len(kept):05d}.png"
        for sub, image in zip(FOLDERS, (r.a, r.b, r.mask), strict=True):
            (work / sub / tmp).write_bytes(png_bytes(image))
        kept.append((v, RenderedView(
            -1, v.parent, v.strategy, v.params, v.coverage, v.camera, tmp, r.coverage_a, r.coverage_b, r.valid,
            r.change_ratio, r.points_read, r.ignore, r.filled, v.probe_valid, r.change_visible,
        )))  # fmt: skip
    if not kept:
        raise PairError(
            f"pair {plan.pair_id}: every rendered view had less than {params.min_valid:.0%} valid pixels "
            f"({low_valid} views); lower --min-valid or check the scenes' overlap."
        )
    rejected = views.all_rejected() | ({"low_valid": low_valid} if low_valid else {})
    return kept, dict(sorted(rejected.items()))


def _index(
    kept: list[tuple[SyntheticView, RenderedView]], work: Path, seed: int
) -> list[tuple[SyntheticView, RenderedView]]:
    """The kept views in key order, indexed 0..n-1 (an order that does not depend on the pool), their
    files renamed to ``<index>.png``."""
    by_view = {id(v): rec for v, rec in kept}
    out = []
    for i, v in enumerate(key_sorted([v for v, _ in kept], seed)):
        rec = by_view[id(v)]
        name = f"{i:04d}.png"
        for sub in FOLDERS:
            move(work / sub / rec.file, work / sub / name)
        out.append((v, replace(rec, index=i, file=name)))
    return out


def changes_seen(
    changes: PairChanges, views: ViewSet, kept: list[tuple[SyntheticView, RenderedView]]
) -> ChangesSeen:
    """Which rendered views show each changed region (planned from their probes), and why a region
    in fewer than asked is (the views' reason; ``low_valid`` when views planned for it were
    rendered with too few valid pixels and replaced)."""
    p = views.params
    regions = []
    for r, region in enumerate(changes.regions):
        shown = tuple(rec.index for v, rec in kept if r in v.shows)
        reason = None
        if len(shown) < p.change_views:
            reason = views.unseen.get(r, "low_valid")
        regions.append(ChangedRegion(
            region.id, region.sides, region.area_m2, region.center_m, region.size_m, shown, reason,
        ))  # fmt: skip
    return ChangesSeen(p.change_views, p.change_min_px, p.change_min_m2, changes.smaller, tuple(regions))


def execute_pair(
    plan: PairPlan, store: Store, device: str = "cpu", progress: Progress = no_progress
) -> PairOutput:
    """Make the outputs of ``plan``: labels (reused when published), views and renders, published
    whole (A/, B/, label/ PNGs and summary.json)."""
    t1, t2 = (open_labelled(sc.tiles, sc.label_set) for sc in (plan.t1, plan.t2))
    labels = pair_labels(plan, t1, t2, store, progress)
    scenes = LabelledPair.with_labels(t1, t2, labels.uri)
    view_params = plan.params.view_params_spec()
    changes = None
    if view_params.change_views > 0:
        changes = pair_changes(scenes, plan.fence, view_params.change_min_m2, labels.radius_m)
        log.info(
            "pair %d: %d changed regions of %g m2 or more (%d smaller)",
            plan.pair_id, len(changes.regions), view_params.change_min_m2, changes.smaller,
        )  # fmt: skip
    threads = CpuThreads()
    try:
        views = pair_views(plan, t1, t2, progress, threads, changes)
    finally:
        threads.restore()
    with store.publish(plan.root) as work:
        kept, rejected = _render_all(plan, scenes, views, work, device, progress)
        indexed = _index(kept, work, plan.params.seed)
        records = [rec for _, rec in indexed]
        summary: PairSummary = {
            "pair": plan.pair_id, "t1": plan.t1.id, "t2": plan.t2.id, "radius_m": labels.radius_m,
            "params": plan.params.to_dict(), "label_sets": plan.versions.to_dict(), "labels": labels.to_dict(),
            "ground_plane": views.ground_choice.plane.to_dict() if views.ground_choice else views.ground.to_dict(),
            "ground": views.ground_choice.to_dict() if views.ground_choice else None, "fence": plan.fence_source, "colour": plan.colour.to_dict(),
            "change_rule": plan.change_rule.to_dict(),
            "candidates": views.candidates, "probed": views.probed, "rejected": rejected,
            "views": [r.to_dict() for r in records],
        }  # fmt: skip
        if changes is not None:
            summary["changes"] = changes_seen(changes, views, indexed).to_dict()
        (work / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    log.info(
        "pair %d: %d views rendered (%s rejected) into %s",
        plan.pair_id, len(records), rejected.get("low_valid", 0), plan.root,
    )  # fmt: skip
    return output_of(plan, summary)
