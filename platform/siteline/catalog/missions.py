"""Catalog queries on missions and their files, and the writes of an ingest: the mission, its files,
its scene with cameras and label set 1, and the pairs the scene forms. Functions take a session and
never commit: the caller owns the transaction."""

from __future__ import annotations

from dataclasses import dataclass

import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.catalog.models import LabelSet, Mission, MissionFile, Scene
from siteline.catalog.pairs import ensure_pair, supersede_pair
from siteline.catalog.scenes import add_cameras, neighbours, scene_at, scene_row, scene_statistics
from siteline.catalog.sites import lock_site
from siteline.catalog.stages import add_completed
from siteline.errors import MissionError, TileError
from siteline.records.mission import CheckedMission, LasLocation
from siteline.records.runs import StageRun
from siteline.records.scene import SceneStatistics
from siteline.records.site import SiteKey


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
        bounds={"min": scan.bounds_min, "max": scan.bounds_max}, registration=checked.registration.to_dict(),
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


def mission_by_manifest(session: Session, sha256: str, site_id: int) -> Mission | None:
    """The mission of manifest ``sha256`` ingested into site ``site_id`` (a mission may go into
    several sites), or None."""
    return session.execute(
        sa.select(Mission).where(Mission.manifest_sha256 == sha256, Mission.site_id == site_id)
    ).scalar_one_or_none()


def mission_files(session: Session, mission_id: int) -> list[MissionFile]:
    return list(
        session.execute(
            sa.select(MissionFile).where(MissionFile.mission_id == mission_id).order_by(MissionFile.path)
        ).scalars()
    )


def list_missions(session: Session, site: SiteKey | None = None) -> list[Mission]:
    q = sa.select(Mission).order_by(Mission.received_at, Mission.id)
    if site is not None:
        q = q.where(Mission.site_id == site.id)
    return list(session.execute(q).scalars())


def mission_file(session: Session, mission_id: int, path: str | None) -> MissionFile | None:
    """The file ``path`` of mission ``mission_id``, or None."""
    return session.execute(
        sa.select(MissionFile).where(MissionFile.mission_id == mission_id, MissionFile.path == path)
    ).scalar_one_or_none()


def blobs_in_use(session: Session, shas: list[str]) -> set[str]:
    """Which of ``shas`` the catalog references (blobs another ingest committed): a mission's file or a
    scene's alignment sample."""
    if not shas:
        return set()
    files = session.execute(sa.select(MissionFile.sha256).where(MissionFile.sha256.in_(shas))).scalars()
    sample = Scene.statistics["stable_sample_sha256"].as_string()
    return set(files) | set(session.execute(sa.select(sample).where(sample.in_(shas))).scalars())


def las_location(session: Session, scene_id: int) -> LasLocation:
    """Where scene ``scene_id``'s point cloud is kept; :class:`TileError` when its mission records none."""
    scene = scene_row(session, scene_id)
    stats = scene_statistics(scene)
    mission = session.get(Mission, scene.mission_id)
    row = mission_file(session, scene.mission_id, stats.las_file)
    if mission is None or row is None:
        raise TileError(f"scene {scene_id}: its mission records no point cloud file.")
    return LasLocation(mission.storage, mission.root_uri, row.path, row.sha256)  # type: ignore[arg-type]
