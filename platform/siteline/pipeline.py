"""The pipeline's order, written once (DESIGN.md §1): ingest -> tile -> process pairs -> build release
-> publish. The CLI, the demo, the flows and the tests call these; each stage function below it does
only its own stage (plan -> execute -> record) and refuses, naming the command, when a precondition
is missing. No Prefect here."""

from __future__ import annotations

import logging
import math
import shutil
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from siteline.catalog import Catalog
from siteline.catalog.context import StageContext
from siteline.catalog.deletion import Deletion, delete_rows, plan_scene_deletion, plan_site_deletion
from siteline.catalog.labelsets import labelled_source
from siteline.catalog.pairs import pair_ids_of_scene, scene_ids_of_pairs, unprocessed_pairs
from siteline.catalog.sites import get_site, imported_label_sets
from siteline.catalog.sites import redefine_site as redefine_catalog_site
from siteline.config import Settings
from siteline.errors import LabelSetError, ReleaseError
from siteline.ingest.options import IngestOptions
from siteline.ingest.stage import IngestResult, ingest_mission
from siteline.labelsets.store import open_labelled
from siteline.pairs.render import LabelledPair
from siteline.pairs.stage import process_pair
from siteline.pointpass import TilingResources
from siteline.previews.cloud import PairCloud
from siteline.records.pairs import ColourPlan, PairOutput
from siteline.records.params.pairs import PairParams
from siteline.records.params.release import ReleaseKnobs, ReleaseParams
from siteline.records.release import Manifest, ReleaseInfo, ReleaseOptions
from siteline.release.plan import choose_release, release_params
from siteline.release.stage import build_release
from siteline.schema import JSON
from siteline.site.fence import validate_fence
from siteline.site.taxonomy import Taxonomy
from siteline.stores import layout
from siteline.tiles.stage import TileOutcome, tile_scene

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Ingested:
    """An ingest and the tiling of its scene (None when the mission made no new scene to tile)."""

    ingest: IngestResult
    tiles: TileOutcome | None

    def to_dict(self) -> dict[str, JSON]:
        """The ingest's record with the tiling's (``tiles``: None when nothing was tiled)."""
        tiling = self.tiles.tiling if self.tiles is not None else None
        return self.ingest.to_dict() | {"tiles": tiling.to_dict() if tiling is not None else None}

    def summary(self) -> str:
        """One line: what happened, and for a new scene its points, cameras and pairs."""
        r = self.ingest
        if not r.created:
            return r.message
        points = r.scan.point_count if r.scan else 0
        reg = r.registration
        flown = (
            f" at {reg.survey.altitude_m:g} m ({reg.altitude_why})"
            if reg.source == "planned" and reg.survey is not None and reg.survey.altitude_m
            else ""
        )
        return (
            f"{r.message}: {points:,} points, {reg.images or 0} {reg.source} cameras{flown}, pairs {r.pairs}"
        )


def ingest(
    ctx: StageContext,
    mission_dir: Path,
    site: str,
    opts: IngestOptions | None = None,
    workers: int = 2,
) -> Ingested:
    """Ingest ``mission_dir`` as a scene of ``site`` and tile it. A mission already ingested is not
    ingested again; its scene is tiled if it is not yet."""
    result = ingest_mission(ctx, Path(mission_dir), site, opts, workers=workers)
    if result.scene_id is None:
        return Ingested(result, None)
    tiled = tile_scene(ctx, result.scene_id, resources=TilingResources(workers))
    if tiled.tiling is not None:
        result.message += f"; {tiled.message}"
    return Ingested(result, tiled)


def tile_scenes(
    ctx: StageContext,
    scene_ids: Iterable[int],
    resources: TilingResources = TilingResources(),
) -> list[TileOutcome]:
    """Tile every scene of ``scene_ids`` that is not tiled yet, or was tiled under an earlier version
    of its site's taxonomy or fence, with ``resources`` (workers, or a Dask cluster's executor): what
    each tiling did (the tile stage's plan decides which scenes need it; those left alone are not
    listed)."""
    outcomes = (tile_scene(ctx, sid, resources=resources) for sid in scene_ids)
    return [o for o in outcomes if o.tiling is not None]


def redefine_site(
    ctx: StageContext,
    site: str,
    taxonomy: Taxonomy | None = None,
    fence: Sequence[Sequence[float]] | None = None,
    clear_fence: bool = False,
    workers: int = 2,
) -> tuple[int, list[TileOutcome]]:
    """Give ``site`` a new taxonomy and/or fence (a closed ring, site-local metres; ``clear_fence``:
    none) as its next version, then tile its scenes again under it (their classes mapped anew from
    their point clouds; label set 1 and the pairs' outputs follow, the outputs keyed by the new
    tiling), and carry each scene's newest imported label set over: its corrections (the points it
    changed from label set 1) exported first (kept under ``SITELINE_HOME/exports/``), then imported
    onto the new tiles' label set 1 with their classes matched by name (points now outside the fence
    become ignore), so the new mapping holds everywhere else. Return the version and what tiling and carrying
    did. A re-tiling cut short is finished by the next ``release build`` (a scene tiled under an
    earlier version is tiled again before its pairs); a carried file that cannot be imported (a
    class the new taxonomy lacks) is named, to import with ``--taxonomy-map``."""
    from siteline.labelsets.export import export_corrections
    from siteline.labelsets.stage import ImportOptions, import_labels

    ring = None
    if fence is not None:
        ring = [list(v) for v in validate_fence(fence, source=f"site {site} fence")]
    with ctx.catalog.transaction() as s:
        carry = imported_label_sets(s, site)
        old = get_site(s, site).spec
    folder = ctx.settings.home / "exports" / f"{site}-v{old.version}"
    files = {}
    for sid, version in sorted(carry.items()):
        files[sid] = folder / f"scene-{sid}-label-set-{version}.laz"
        files[sid].parent.mkdir(parents=True, exist_ok=True)
        if export_corrections(ctx.catalog, sid, version, files[sid]) == 0:  # it corrected nothing
            files.pop(sid).unlink(missing_ok=True)
    with ctx.catalog.transaction() as s:
        row, scene_ids = redefine_catalog_site(s, site, taxonomy, ring, clear_fence)
        version, now = row.spec.version, row.spec
    log.info("site %s is at version %d: tiling its %d scenes again", site, version, len(scene_ids))
    outcomes = tile_scenes(ctx, scene_ids, TilingResources(workers))
    kept = {c.name for c in now.taxonomy.classes}  # a class the new taxonomy dropped is named by the import
    by_name: dict[int, str | int] = {c.id: c.name for c in old.taxonomy.classes if c.name in kept}
    for sid, path in files.items():
        try:
            how = ImportOptions(by_name, f"carried to site version {version} from {path.name}", carried=True)
            done = import_labels(ctx, sid, path, how)
            message = (
                f"scene {sid}: corrections of label set {carry[sid]} carried over as label set {done.version}"
            )
        except LabelSetError as exc:
            message = (
                f"scene {sid}: corrections of label set {carry[sid]} not carried ({exc}); its file is {path}"
            )
        log.info(message)
        outcomes.append(TileOutcome(None, message))
    return version, outcomes


def process_pairs(
    ctx: StageContext,
    pair_ids: Iterable[int],
    params: PairParams | None = None,
    device: str = "cpu",
    label_sets: Mapping[int, int] | None = None,
) -> dict[int, PairOutput]:
    """Tile the pairs' scenes where needed, then process every pair (outputs are reused when made)
    with each scene's newest label set, or the version ``label_sets`` (scene id -> version) pins."""
    ids = list(pair_ids)
    with ctx.catalog.transaction() as s:
        scene_ids = scene_ids_of_pairs(s, ids)
    tile_scenes(ctx, scene_ids)
    return {pid: process_pair(ctx, pid, params, device, label_sets) for pid in ids}


def pending_pairs(catalog: Catalog, scene_id: int) -> list[int]:
    """The pairs of ``scene_id`` nobody processed yet (no outputs under any parameters): whether a
    mission ingested again still has work to announce."""
    with catalog.transaction() as s:
        return unprocessed_pairs(s, pair_ids_of_scene(s, scene_id))


def release_parameters(catalog: Catalog, site: str, knobs: ReleaseKnobs | None = None) -> ReleaseParams:
    """What a release of ``site`` built now would use: its release settings with ``knobs`` over them,
    auto knobs worked out (refused when its images would be too small)."""
    with catalog.transaction() as s:
        return release_params(s, site, knobs, f"a release of site {site}")


def release(
    ctx: StageContext,
    site: str,
    name: str,
    knobs: ReleaseKnobs | None = None,
    options: ReleaseOptions = ReleaseOptions(),
) -> ReleaseInfo:
    """Everything a release of ``site`` needs, in order: its parameters (the site's release settings
    with ``knobs`` over them, siteline.release.knobs: refused before any work when its images would be
    too small), the pairs (``options.pair_ids`` or all) processed on ``options.device`` on each
    scene's newest label set (or the version ``options.label_sets`` pins), a draft built from exactly
    those outputs, published when ``options.publish``; or the latest version when it already has these
    inputs (``up_to_date``)."""
    with ctx.catalog.transaction() as s:  # refused before any pair is processed
        choice = choose_release(s, site, name, knobs, options)
    chosen, params = list(choice.pair_ids), choice.params
    # each pair's rule is stated before any pair is processed, not found in the masks afterwards
    for pid, rule in choice.rules.items():
        if rule.differences:
            other = "geometry" if rule.rule == "semantic" else "semantic"
            log.warning(
                "release %s, pair %d: the scenes classify differently (%s); its change labels use the %s "
                "rule (%s; --change-rule %s to change it)",
                name, pid, "; ".join(rule.differences), rule.rule, rule.why, other,
            )  # fmt: skip
    log.info("release %s of site %s: %d pairs, scale %g, %d px points, %d views", name, site, len(chosen),
             params.pair.scale, params.pair.point_size_px, params.pair.views)  # fmt: skip
    outputs = process_pairs(ctx, chosen, params.pair, options.device, options.label_sets)
    for out in outputs.values():
        if out.radius_m > params.radius_ceiling_m:
            radius = out.labels.radius
            spacing = max(radius.median_spacing_m.values(), default=float("nan")) if radius else float("nan")
            log.warning(
                "release %s, pair %d: change radius %.2f m (the sparser scene's points lie %.2f m apart) is above "
                "the radius ceiling %.2f m: a change smaller than %.2f m is labelled unchanged. Survey denser, or "
                "accept it with --radius-ceiling %.2g",
                name, out.pair_id, out.radius_m, spacing, params.radius_ceiling_m, out.radius_m, math.ceil(out.radius_m * 10) / 10,
            )  # fmt: skip
    # build on the label sets the outputs used, even if a newer one was imported meanwhile
    used = {
        sid: v
        for out in outputs.values()
        for sid, v in ((out.t1, out.versions.t1), (out.t2, out.versions.t2))
    }
    built = replace(options, label_sets=used)  # the pairs are the choice's
    return build_release(ctx, site, name, choice, built)


def pair_cloud(catalog: Catalog, settings: Settings, doc: Manifest, pair_id: int) -> PairCloud:
    """Pair ``pair_id`` of the release whose manifest is ``doc``, opened for the 3D viewer: its scenes
    as the release saw them (the label sets and change labels of its lineage), its colour, the site's
    taxonomy and the release's items of the pair. :class:`ReleaseError` when the release has no such
    pair, or the scenes were tiled again or their labels deleted since (the points no longer match)."""
    lineage = doc.lineage
    what = f"release {doc.title}"
    pair = next((p for p in lineage["pairs"] if int(p["id"]) == pair_id), None)
    if pair is None:
        have = ", ".join(str(p["id"]) for p in lineage["pairs"])
        raise ReleaseError(f"{what} has no pair {pair_id} (its pairs: {have}).")
    scenes = {int(sc["id"]): sc for sc in lineage["scenes"]}
    label_uri = settings.store.resolve(str(pair["labels"]["uri"]))  # relative to this home's store
    if not settings.store.is_complete(label_uri):
        # the manifest's own (relative) address: the message is served to HTTP clients
        raise ReleaseError(
            f"{what}, pair {pair_id}: its change labels ({pair['labels']['uri']}) are gone (deleted since)."
        )
    with catalog.transaction() as s:
        opened = []
        for key in ("t1", "t2"):
            sid = int(pair[key])
            source, ref = labelled_source(s, sid, int(pair["label_sets"][key]))
            made = scenes[sid].get("tile_checksum") if sid in scenes else None
            if made is not None and made != source.checksum:
                raise ReleaseError(
                    f"{what}, pair {pair_id}: scene {sid} was tiled again since the release was built; its points no "
                    "longer match the release's labels."
                )
            opened.append(open_labelled(source, ref))
        taxonomy = get_site(s, lineage["sites"][0]["name"]).spec.taxonomy
    items = tuple(it for it in doc.items if it.pair == pair_id)
    return PairCloud(
        pair_id, LabelledPair.with_labels(opened[0], opened[1], label_uri),
        ColourPlan.from_dict(pair.get("colour") or {"source": pair.get("colour_source", "rgb")}), taxonomy, items,
    )  # fmt: skip


@dataclass(frozen=True)
class Deleted:
    """What a deletion removed: scenes, pairs, draft releases ("name version"), stores and blobs, and
    the pairs it made again between the scenes around a deleted one."""

    scenes: tuple[int, ...]
    pairs: tuple[int, ...]
    drafts: tuple[str, ...]
    stores: int
    blobs: int
    repaired: tuple[int, ...]

    def message(self, what: str) -> str:
        text = (
            f"deleted {what}: {len(self.scenes)} scene(s), {len(self.pairs)} pair(s), {self.stores} store(s), "
            f"{self.blobs} mission blob(s)"
        )
        if self.drafts:
            text += f", draft release(s) {', '.join(self.drafts)}"
        if self.repaired:
            text += f"; the scenes around it are paired again (pair {', '.join(map(str, self.repaired))})"
        return text


def delete_scene(catalog: Catalog, settings: Settings, scene_id: int) -> Deleted:
    """Delete scene ``scene_id``: its stores, pairs (their outputs and previews), the drafts built on
    them, its mission (and the blobs no other mission names), then its rows; the scenes just before
    and after it become a pair again. Refused, nothing touched, while a published release was built
    on one of its pairs. A deletion cut short leaves rows naming missing stores; run it again."""
    with catalog.lock(f"scene:{scene_id}:tiles"), catalog.transaction() as s:
        plan = plan_scene_deletion(s, scene_id)
    return _delete(catalog, settings, plan)


def delete_site(catalog: Catalog, settings: Settings, name: str) -> Deleted:
    """Delete site ``name`` with every scene of it (as :func:`delete_scene`), refused while a
    published release was built on one of its pairs."""
    with catalog.transaction() as s:
        plan = plan_site_deletion(s, name)
    return _delete(catalog, settings, plan)


def _delete(catalog: Catalog, settings: Settings, plan: Deletion) -> Deleted:
    store, home = settings.store, settings.home
    stores = [*plan.stores]
    for pid in plan.pairs:
        stores += [layout.pair_folder(store, pid), *layout.pair_label_stores(store, pid)]
    for uri in stores:  # stores first: rows that outlive a crash name what is gone, never the reverse
        store.remove(uri)
    for pid in plan.pairs:
        shutil.rmtree(layout.previews(home) / "pairs" / f"pair-{pid}", ignore_errors=True)
    for name, version in plan.drafts:
        shutil.rmtree(layout.release_draft(home, name, version), ignore_errors=True)
    with catalog.transaction() as s:
        repaired = delete_rows(s, plan)
    for sha in plan.blobs:
        store.remove(layout.blob(store, sha))
    log.info("%s deleted (%d stores, %d blobs)", plan.what, len(stores), len(plan.blobs))
    return Deleted(
        plan.scenes, plan.pairs, tuple(f"{n} {v}" for n, v in plan.drafts), len(stores), len(plan.blobs),
        tuple(repaired),
    )  # fmt: skip
