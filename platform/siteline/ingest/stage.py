"""The ingest stage: the mission folder's manifest, then plan (catalog) -> execute (read, check and
store the mission) -> record (catalog) (DESIGN.md §1, §2, §3, §9).

Order matters for "nothing half-written": the mission's files are copied beside the store while it is
read and checked (the copy and its flush to disk overlap the reading), appear in the
content-addressed store only once every check passed, and only then one transaction writes the
catalog rows. A failure before the commit drops the copies and removes the blobs this ingest added
(and no other's: under a lock (``BLOBS_LOCK``), the blobs the catalog references stay, and an
ingest about to record its mission stores again any blob it had found stored that such a removal
took)."""

from __future__ import annotations

import logging
import shutil
from dataclasses import dataclass, field, fields
from pathlib import Path

import sqlalchemy as sa

from siteline.catalog.context import StageContext
from siteline.catalog.missions import blobs_in_use, record_ingest
from siteline.catalog.sites import get_site
from siteline.errors import MissionError
from siteline.ingest.execute import execute_ingest, restore_blobs, stage_mission, store_mission
from siteline.ingest.inventory import mission_manifest
from siteline.ingest.options import IngestOptions
from siteline.ingest.plan import IngestPlan, plan_ingest
from siteline.ingest.pointcloud import start_readers
from siteline.pointpass import PartitionCache
from siteline.progress import step
from siteline.records.mission import CheckedMission
from siteline.records.registration import Registration
from siteline.records.runs import StageRun
from siteline.records.scan import LasScan
from siteline.schema import JSON
from siteline.stores import layout
from siteline.stores.blobs import BlobStaging, remove_blobs

log = logging.getLogger(__name__)
# held while an ingest records its mission or a failed one removes the blobs it added
BLOBS_LOCK = "store:blobs"


@dataclass
class IngestResult:
    """What ``ingest_mission`` did: whether it created a scene, one sentence saying so, the mission
    and scene ids, the manifest hash and file count, the LAS scan and registration records, and the
    pairs the new scene forms."""

    created: bool
    message: str
    mission_id: int
    scene_id: int | None
    manifest_sha256: str
    files: int = 0
    scan: LasScan | None = None
    registration: Registration = field(default_factory=lambda: Registration("unknown"))
    pairs: list[int] = field(default_factory=list)

    def to_dict(self) -> dict[str, JSON]:
        doc = {f.name: getattr(self, f.name) for f in fields(self)}
        return doc | {
            "scan": self.scan.to_dict() if self.scan is not None else {},
            "registration": self.registration.to_dict(),
        }


def _already(plan: IngestPlan) -> IngestResult:
    assert plan.existing is not None
    ex, m = plan.existing, plan.manifest
    scene = f" (scene {ex.scene_id})" if ex.scene_id is not None else ""
    log.info("mission %s is already ingested as mission %d", m.root.name, ex.mission_id)
    return IngestResult(
        False, f"mission {m.root.name} is already ingested as mission {ex.mission_id}{scene}: nothing new.",
        ex.mission_id, ex.scene_id, m.sha256, len(m.entries),
    )  # fmt: skip


def _store_and_record(
    ctx: StageContext,
    plan: IngestPlan,
    checked: CheckedMission,
    run: StageRun,
    staging: BlobStaging | None,
) -> IngestResult:
    new_blobs: list[str] = []
    try:
        store_mission(checked, ctx.settings.store, new_blobs, staging, ctx.progress)
        # one registration per site at a time: pairs are formed from the scenes around this one; the
        # blobs lock keeps a failed ingest from removing a shared blob between restore and commit
        with ctx.catalog.lock(f"site:{plan.site_id}:scenes"), ctx.catalog.lock(BLOBS_LOCK):
            restore_blobs(checked, ctx.settings.store, new_blobs)
            with ctx.catalog.transaction() as s:
                ids = record_ingest(s, plan.site_id, checked, run)
    except BaseException as exc:
        with ctx.catalog.lock(BLOBS_LOCK):
            with ctx.catalog.transaction() as s:
                shared = blobs_in_use(s, new_blobs)
            # content another mission committed meanwhile stays; only this ingest's own blobs go
            remove_blobs(ctx.settings.store, [b for b in new_blobs if b not in shared])
        if isinstance(exc, sa.exc.IntegrityError):
            raise MissionError(
                f"mission {checked.manifest.root.name} conflicts with one ingested at the same time "
                f"({exc.orig}); nothing was ingested."
            ) from exc
        raise
    message = f"mission {checked.name} ingested as scene {ids.scene_id} of site {plan.site.name}"
    notes = _notes(checked.registration)
    if notes:
        message += f" ({'; '.join(notes)})"
    log.info("%s; pairs %s", message, list(ids.pairs))
    return IngestResult(
        True, message, ids.mission_id, ids.scene_id, checked.manifest.sha256, len(checked.manifest.entries),
        checked.scan, checked.registration, list(ids.pairs),
    )  # fmt: skip


def _notes(registration: Registration) -> list[str]:
    """What the one-line report of an ingest says beside it: a scene without cameras, and the
    directions its co-registration could not check."""
    notes = []
    if registration.source == "none" and registration.note:
        notes.append(registration.note)
    alignment = registration.alignment
    if alignment is not None and alignment.free:
        notes.append(
            f"co-registration onto scene {alignment.against_scene} could not check {', '.join(alignment.free)}: "
            f"too little in the scenes fixes {'it' if len(alignment.free) == 1 else 'them'}"
        )
    return notes


def ingest_mission(
    ctx: StageContext,
    mission_dir: Path,
    site_name: str,
    opts: IngestOptions | None = None,
    workers: int = 2,
) -> IngestResult:
    """Inventory, validate, georegister and register ``mission_dir`` as a scene of ``site_name``; a
    mission already ingested (same manifest) is not ingested again. The point cloud is read over
    ``workers`` processes, and its partition into tile runs is kept for the tile stage."""
    opts = opts or IngestOptions()
    with ctx.catalog.transaction() as s:
        get_site(s, site_name)  # an unknown site is refused before a byte is hashed
    start_readers(Path(mission_dir), workers)  # they start up while the mission is hashed
    manifest = mission_manifest(Path(mission_dir), step(ctx.progress, "hashing"))
    # one ingest of a mission's content at a time: a copy dropped twice at once is ingested once
    cache = PartitionCache(layout.partitions(ctx.settings.home))
    with ctx.catalog.lock(f"mission:{manifest.sha256}"):
        with ctx.catalog.transaction() as s:
            plan = plan_ingest(s, site_name, manifest)
        if plan.existing is not None:
            cache.sweep_unfinished()  # what a killed run of it left
            return _already(plan)
        run = StageRun("ingest", f"mission:{manifest.sha256}", opts.record(site_name), run_id=ctx.run_id)
        runs = cache.new_folder()
        staging = stage_mission(manifest, opts.storage, ctx.settings.store)
        try:
            checked = execute_ingest(plan, opts, ctx.settings.store, ctx.progress, workers, runs)
            result = _store_and_record(ctx, plan, checked, run, staging)
            aligned = checked.registration.alignment
            if aligned is None or not aligned.applied:
                # the runs were cut before the co-registration: a corrected scene's tiles cut anew
                cache.keep(runs, checked.las_sha256)
            return result
        finally:
            if staging is not None:
                staging.close()
            shutil.rmtree(runs, ignore_errors=True)
