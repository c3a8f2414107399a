"""The release stages. Build: plan (catalog) -> execute (the pairs' outputs found, the draft written) ->
record (catalog). Publish: plan -> execute (verify, move into place) -> record -> read-only."""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

from siteline.catalog import Catalog
from siteline.catalog.context import StageContext
from siteline.catalog.releases import get_release, record_draft, record_published, release_item_counts
from siteline.errors import ReleaseError
from siteline.pairs.outputs import find_outputs
from siteline.records.pairs import PairOutput
from siteline.records.release import ReleaseInfo, ReleaseOptions
from siteline.records.runs import StageRun
from siteline.release import layout
from siteline.release.build import execute_build
from siteline.release.manifest import read_manifest
from siteline.release.plan import ReleaseChoice, ReleasePlan, check_release_name, plan_publish, plan_release
from siteline.release.publish import make_read_only, move_back, move_into_place
from siteline.release.repair import inspect_release, mend

log = logging.getLogger(__name__)


def build_release(
    ctx: StageContext,
    site_name: str,
    name: str,
    choice: ReleaseChoice,
    options: ReleaseOptions = ReleaseOptions(),
) -> ReleaseInfo:
    """Assemble a draft release ``name`` from the processed pairs of ``choice`` (its pairs and resolved
    parameters: siteline.release.plan.choose_release) in format 2 (siteline.release.layout), and
    publish it when ``options.publish``, holding the release name's lock throughout. Every pair must
    already be processed with these parameters and label sets: :class:`ReleaseError` names the
    command otherwise (``siteline.pipeline.release`` processes what is missing first). Each scene's
    newest label set is used unless ``options.label_sets`` (scene id -> version) pins one. When the
    latest version's inputs are these (pairs, their outputs, label sets, parameters), nothing is
    built: that version is returned with ``up_to_date`` (published now if it is a draft and
    ``options.publish``)."""
    check_release_name(name)  # before anything: a name is a folder name
    version, label_sets, publish = options.version, options.label_sets, options.publish
    with ctx.catalog.lock(f"release:{name}"):  # one builder or publisher of a release name at a time
        with ctx.catalog.transaction() as s:
            plan = plan_release(s, ctx.settings, site_name, name, choice, version, label_sets)
        if plan.up_to_date is not None:
            info = _release_info(ctx.catalog, name, plan.up_to_date)
            log.info("release %s is up to date: %s %s has these inputs", name, name, info.version)
        else:
            info = _build(ctx, plan)
        if publish and info.status == "draft":
            info = _publish(ctx, name, info.version)
        return replace(info, reason=plan.reason if plan.up_to_date is None else info.reason,
                       up_to_date=plan.up_to_date is not None)  # fmt: skip


def _release_info(catalog: Catalog, name: str, version: str) -> ReleaseInfo:
    """A recorded release version as commands report it (its statistics from its manifest)."""
    with catalog.transaction() as s:
        rel = get_release(s, name, version)
        items = sum(release_item_counts(s, rel.id).values())
        status, root, sha = rel.status, str(rel.root_uri), rel.manifest_sha256
        reason = (rel.parameters or {}).get("version_reason", "")
    return ReleaseInfo(name, version, status, root, items, sha, read_manifest(Path(root)).stats, reason)  # type: ignore[arg-type]


def _build(ctx: StageContext, plan: ReleasePlan) -> ReleaseInfo:
    params = plan.params
    run = StageRun(
        "build_release", f"release:{plan.name}:{plan.version}",
        {"pair_params": params.pair.to_dict(), "preset": params.preset, "pairs": [p.pair_id for p in plan.pairs]},
        run_id=ctx.run_id,
    )  # fmt: skip
    found = {p.pair_id: find_outputs(p, ctx.settings.store) for p in plan.pairs}
    missing = [pid for pid, out in found.items() if out is None]
    if missing:
        raise ReleaseError(
            f"pair {missing[0]} is not processed with these parameters and label sets ({len(missing)} of "
            f"{len(found)} pairs): run `siteline release build`, which processes pairs first. Nothing was written."
        )
    outputs: dict[int, PairOutput] = {pid: out for pid, out in found.items() if out is not None}
    draft = execute_build(plan, outputs, ctx.progress)
    with ctx.catalog.transaction() as s:
        record_draft(s, draft, tuple(layout.FOLDERS), run)
    return ReleaseInfo(
        plan.name, plan.version, "draft", draft.root, len(draft.items), draft.manifest_sha256, draft.stats,
        plan.reason,
    )  # fmt: skip


def publish_release(ctx: StageContext, name: str, version: str) -> ReleaseInfo:
    """Verify the draft's checksums, move it into place, mark it published, make it read-only; a
    publish an earlier one left half-way (moved but not recorded, or recorded but still writable)
    is finished instead."""
    with ctx.catalog.lock(f"release:{name}"):
        return _publish(ctx, name, version)


def _publish(ctx: StageContext, name: str, version: str) -> ReleaseInfo:
    with ctx.catalog.transaction() as s:
        # a publish killed after its catalog commit left the version published but writable: finish it
        writable_left = [f for f in inspect_release(s, ctx.settings, name, version) if f.kind == "writable"]
        if not writable_left:
            plan = plan_publish(s, ctx.settings, name, version)
            unfinished = [
                f for f in inspect_release(s, ctx.settings, name, version) if f.kind == "moved-not-recorded"
            ]
    if writable_left:
        log.info("%s", writable_left[0].message)
        mend(ctx, writable_left[0])
        return _release_info(ctx.catalog, name, version)
    if unfinished:  # an earlier publish moved it into place and died: finish that one
        log.info("%s", unfinished[0].message)
        mend(ctx, unfinished[0])
        return _release_info(ctx.catalog, name, version)
    run = StageRun("publish_release", f"release:{name}:{version}", {}, run_id=ctx.run_id)
    move_into_place(plan)
    try:
        with ctx.catalog.transaction() as s:
            record_published(s, name, version, plan.final, run)
    except BaseException:
        move_back(plan)
        raise
    make_read_only(plan.final)
    log.info("release %s %s published at %s", name, version, plan.final)
    return _release_info(ctx.catalog, name, version)
