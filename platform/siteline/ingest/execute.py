"""Reading and checking a mission from its plan (the execute part of ingest; never touches the
catalog): the LAS scan, photos, georegistration, capture time and the alignment against the previous
scene, then the files stored in the content-addressed store."""

from __future__ import annotations

import hashlib
import io
import logging
from dataclasses import replace
from pathlib import Path

import numpy as np

from siteline.camera.pinhole import Camera
from siteline.camera.poses import Rigid
from siteline.errors import MissionError
from siteline.ingest.mission import capture_time, choose_las, colmap_dir, mission_name, read_photos
from siteline.ingest.options import IngestOptions
from siteline.ingest.plan import IngestPlan
from siteline.ingest.pointcloud import scan_las
from siteline.pointpass import correction_rigid
from siteline.progress import Progress, no_progress, step
from siteline.records.mission import CheckedMission, MissionManifest
from siteline.records.scan import LasScan
from siteline.register.scene import AlignmentPolicy, check_alignment, planned_cameras, register_cameras
from siteline.site.crs import parse_z_unit
from siteline.site.spec import SiteSpec
from siteline.stores import Store, layout
from siteline.stores.blobs import BlobStaging, put_blob_bytes

log = logging.getLogger(__name__)


def sample_blob(sample: np.ndarray) -> tuple[bytes, str]:
    """The ``.npy`` bytes of a co-registration sample ((N, 4) float64: site-local x, y, z and the kind
    of surface; samples stored before the kinds were kept are (N, 3) of stable surfaces) and their
    sha256."""
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(sample, dtype=np.float64))
    data = buf.getvalue()
    return data, hashlib.sha256(data).hexdigest()


def load_sample(store: Store, sha256: str | None) -> np.ndarray | None:
    """The alignment sample stored under ``sha256``, None when there is none."""
    if not sha256:
        return None
    uri = layout.blob(store, sha256)
    return np.load(io.BytesIO(store.read_bytes(uri))) if store.exists(uri) else None


def execute_ingest(
    plan: IngestPlan,
    opts: IngestOptions,
    store: Store,
    progress: Progress = no_progress,
    workers: int = 1,
    runs_into: Path | None = None,
) -> CheckedMission:
    """Read and check the mission of ``plan`` (its point cloud over ``workers`` processes): nothing is
    stored yet; the point cloud's tile runs go into the empty folder ``runs_into`` when given
    (siteline.pointpass.partition). :class:`MissionError` (or the error of the check that failed) names
    the file and the problem."""
    root, entries = plan.manifest.root, plan.manifest.entries
    las = choose_las(entries, root)
    z_unit = parse_z_unit(opts.z_unit) if opts.z_unit else None
    scan = scan_las(
        root / las.path, plan.site, opts.crs, z_unit=z_unit, progress=step(progress, "reading points"),
        workers=workers, runs_into=runs_into,
    )  # fmt: skip
    check_codes(scan, root / las.path, plan.site, opts.unmapped_codes)
    scan = scan.at(las.path)
    photos = read_photos(entries, root)
    cameras, registration, source = register_cameras(
        photos, colmap_dir(entries, root), plan.site, opts.ransac_max_error_m, opts.max_georegistration_rms_m
    )
    if not cameras or opts.plan_cameras:
        survey = scan.survey_sample if scan.survey_sample is not None else np.zeros((0, 5))
        cameras, registration, source = planned_cameras(
            survey, scan.footprint, plan.site, opts.survey, len(photos), scan.density_pts_m2
        )
        if not cameras:
            log.warning(
                "point cloud %s: %s; it is ingested and tiled all the same",
                root / las.path,
                registration.note,
            )
    when, when_source = capture_time(photos, entries, scan, root, opts.captured_at)
    if plan.scene_at(when) is not None:
        raise MissionError(
            f"site {plan.site.name} already has a scene captured at {when.isoformat()}; a different "
            "mission of the same flight? Nothing was ingested."
        )
    before = plan.scene_before(when)
    sample = load_sample(store, before.statistics.stable_sample_sha256) if before is not None else None
    if before is not None and sample is not None and scan.stable_sample is not None:
        policy = AlignmentPolicy(opts.max_alignment_translation_m, opts.max_alignment_residual_m)
        alignment = check_alignment(
            scan.stable_sample, sample, before.id, root.name, policy, opts.accept_misalignment
        )
        registration = registration.aligned(alignment)
        if alignment.applied:
            scan, cameras = corrected(scan, cameras, alignment.correction)
            log.info(
                "mission %s: co-registered onto scene %d, moved by %.3f m (residual %.3f m)", root.name,
                before.id, alignment.translation_m, alignment.residual_m,
            )  # fmt: skip
    log.info(
        "mission %s: %s points, %d cameras (%s), captured %s (%s)",
        root.name, f"{scan.point_count:,}", len(cameras), source or "none", when.isoformat(), when_source,
    )  # fmt: skip
    _, sample_sha = sample_blob(scan.stable_sample if scan.stable_sample is not None else np.zeros((0, 4)))
    return CheckedMission(
        plan.manifest, mission_name(entries, root), scan, las.sha256, cameras, source or "xmp", registration,
        when, when_source, sample_sha, opts.storage,
    )  # fmt: skip


def check_codes(scan: LasScan, path: Path, site: SiteSpec, unmapped: str) -> None:
    """Refuse a point cloud holding class codes the site taxonomy does not map (unless ``unmapped``
    is ``ignore``), naming the codes, their points and the scheme the file looks like."""
    if not scan.unknown_codes:
        return
    codes = ", ".join(f"{c} ({n:,} points)" for c, n in sorted(scan.unknown_codes.items()))
    if unmapped == "ignore":
        log.warning(
            "point cloud %s: class codes %s are not in site %s's taxonomy: made ignore",
            path,
            codes,
            site.name,
        )
        return
    raise MissionError(
        f"point cloud {path}: class codes {codes} are not mapped by site {site.name}'s taxonomy "
        f"{site.taxonomy.name!r} (the file's codes look like {scan.class_scheme or 'an unknown'} classification). "
        f"Map them in the taxonomy's 'las' source codes and run `siteline site update {site.name} --taxonomy "
        "FILE`, or ingest with --unmapped-codes ignore to make those points ignore. Nothing was ingested."
    )


def corrected(
    scan: LasScan, cameras: dict[str, Camera], correction: tuple[tuple[float, ...], ...]
) -> tuple[LasScan, dict[str, Camera]]:
    """The scan's stable sample and footprint and the scene's cameras moved by a co-registration
    (4 x 4, site-local: previous scene from this one), as its tiles will be (siteline.pointpass.sitestream)."""
    prev_from_new = correction_rigid(correction)
    sample = None
    if scan.stable_sample is not None:
        sample = scan.stable_sample.copy()
        sample[:, :3] = prev_from_new.apply(sample[:, :3])
    outline = None
    if scan.footprint is not None:
        ring = prev_from_new.apply(
            np.c_[np.asarray(scan.footprint, dtype=np.float64), np.zeros(len(scan.footprint))]
        )
        outline = np.round(ring[:, :2], 2).tolist()
    new_from_prev = prev_from_new.inverse()
    moved = {}
    for name, cam in cameras.items():
        pose = Rigid("cam", "new", cam.R, cam.t) @ new_from_prev  # cam_from_prev
        moved[name] = cam.with_pose(pose.R, pose.t)
    return replace(scan, stable_sample=sample, footprint=outline), moved


def stage_mission(manifest: MissionManifest, storage: str, store: Store) -> BlobStaging | None:
    """Start copying the mission's files into the content-addressed store (``copy`` storage), beside
    the reading of the mission; None for ``reference`` storage."""
    if storage != "copy":
        return None
    return BlobStaging(store, [(Path(manifest.root) / e.path, e.sha256) for e in manifest.entries])


def store_mission(
    checked: CheckedMission,
    store: Store,
    new_blobs: list[str],
    staging: BlobStaging | None,
    progress: Progress = no_progress,
) -> None:
    """Put the alignment sample and the files ``staging`` copied (:func:`stage_mission`) into the
    content-addressed store, appending to ``new_blobs`` each blob this call added (so a caller can
    remove them on failure)."""
    _put_sample(checked, store, new_blobs)
    if staging is None:
        return
    total = sum(e.size_bytes for e in checked.manifest.entries)
    progress("storing", 0, total)
    staging.commit(new_blobs)
    progress("storing", total, None)
    log.info("mission %s: %d new blobs stored", checked.name, len(new_blobs))


def restore_blobs(checked: CheckedMission, store: Store, new_blobs: list[str]) -> None:
    """Store again each blob of the mission that is missing, from the mission folder, appending its
    hash to ``new_blobs``: a failed ingest of a mission sharing content removes the blobs it added,
    which this one may have found stored and not copied. Called under the catalog's blobs lock
    (siteline.ingest.stage), so no such removal runs between this check and the catalog's commit."""
    if not store.exists(layout.blob(store, checked.sample_sha256)):
        _put_sample(checked, store, new_blobs)
    if checked.storage != "copy":
        return
    root = Path(checked.manifest.root)
    for entry in checked.manifest.entries:
        dest = layout.blob(store, entry.sha256)
        if not store.exists(dest):
            store.put_file(root / entry.path, dest)
            new_blobs.append(entry.sha256)
            log.warning(
                "mission %s: blob of %s stored again (a failed ingest removed it)", checked.name, entry.path
            )


def _put_sample(checked: CheckedMission, store: Store, new_blobs: list[str]) -> None:
    """Store the mission's alignment sample unless it is stored (appending its hash when new)."""
    sample = checked.scan.stable_sample
    data, sha = sample_blob(sample if sample is not None else np.zeros((0, 3)))
    if put_blob_bytes(store, data, sha):
        new_blobs.append(sha)
