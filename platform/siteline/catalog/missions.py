"""Catalog writes of an ingest: the mission, its files, its scene with cameras and label set 1, and
the pairs the scene forms. Functions take a session and never commit: the caller owns the transaction."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.orm import Session

from siteline.catalog.models import LabelSet, Mission, MissionFile, Scene
from siteline.catalog.scenes import (
    add_cameras,
    ensure_pair,
    lock_site,
    mission_by_manifest,
    neighbours,
    scene_at,
    supersede_pair,
)
from siteline.catalog.stages import add_completed
from siteline.errors import MissionError
from siteline.records.mission import CheckedMission
from siteline.records.runs import StageRun
from siteline.records.scene import SceneStatistics


@dataclass(frozen=True)
class IngestedIds:
    """What an ingest added: the mission, its scene, and the pairs the scene forms with its neighbours."""

    mission_id: int
    scene_id: int
    pairs: tuple[int, ...]


def record_ingest(session: Session, site_id: int, checked: CheckedMission, run: StageRun) -> IngestedIds:
    """Record a checked mission whose files are already stored: the mission and its files, its
    registered scene (statistics, cameras, label set 1), the pairs with the scenes captured just
    before and after, and the stage run. The site row is locked first (one registration per site at
    a time: pairs are formed from the scenes around this one)."""
    site = lock_site(session, site_id)
    manifest = checked.manifest
    if mission_by_manifest(session, manifest.sha256, site.id) is not None:
        raise MissionError(f"mission {manifest.root.name} was ingested concurrently; nothing new.")
    if scene_at(session, site, checked.capture_time) is not None:
        raise MissionError(
            f"site {site.name} already has a scene captured at {checked.capture_time.isoformat()}; a different "
            "mission of the same flight? Nothing was ingested."
        )
    mission = Mission(
        site_id=site.id, manifest_sha256=manifest.sha256, name=checked.name, status="ingested",
        storage=checked.storage, root_uri=str(manifest.root),
    )  # fmt: skip
    session.add(mission)
    session.flush()
    for f in manifest.entries:
        session.add(
            MissionFile(
                mission_id=mission.id, path=f.path, size_bytes=f.size_bytes, sha256=f.sha256, kind=f.kind
            )
        )
    stats = SceneStatistics(
        scan=checked.scan, las_file=checked.scan.path, las_sha256=checked.las_sha256,
        stable_sample_sha256=checked.sample_sha256, photos=sum(e.kind == "photo" for e in manifest.entries),
        cameras=len(checked.cameras), capture_time_source=checked.capture_time_source,
    )  # fmt: skip
    scan = checked.scan
    scene = Scene(
        site_id=site.id, mission_id=mission.id, capture_time=checked.capture_time, point_count=scan.point_count,
        bounds={"min": scan.bounds_min, "max": scan.bounds_max}, registration=checked.registration,
        statistics=stats.to_json(), status="registered",
    )  # fmt: skip
    session.add(scene)
    session.flush()
    if checked.cameras:
        add_cameras(session, scene.id, dict(checked.cameras), checked.camera_source)
    session.add(
        LabelSet(
            scene_id=scene.id, version=1, source=f"las classification ({scan.path})",
            class_histogram=scan.class_histogram,
        )
    )  # fmt: skip
    before, after = neighbours(session, site, checked.capture_time)
    pairs = []
    if before is not None:
        pairs.append(ensure_pair(session, site, before, scene).id)
    if after is not None:
        pairs.append(ensure_pair(session, site, scene, after).id)
    if before is not None and after is not None:
        # a scene that lands between two: pairs follow capture order whatever the arrival order
        supersede_pair(session, before.id, after.id)
    add_completed(session, run)
    return IngestedIds(mission.id, scene.id, tuple(pairs))
