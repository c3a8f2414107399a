"""Catalog writes of an ingest: the mission, its files, its scene with cameras and label set 1, and
the pairs the scene forms. Functions take a session and never commit: the caller owns the transaction."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy.orm import Session

from siteline.cameras import Camera
from siteline.catalog.models import LabelSet, Mission, MissionFile, Scene, Site
from siteline.catalog.scenes import add_cameras, ensure_pair, neighbours


@dataclass(frozen=True)
class FileRow:
    """One file of a mission: POSIX path inside the folder, size in bytes, sha256, kind."""

    path: str
    size_bytes: int
    sha256: str
    kind: str


def record_mission_scene(
    session: Session,
    site: Site,
    *,
    manifest_sha256: str,
    name: str,
    storage: str,
    root_uri: str,
    files: list[FileRow],
    capture_time: datetime,
    point_count: int,
    bounds: dict[str, list[float]],
    registration: dict[str, Any],
    statistics: dict[str, Any],
    cameras: dict[str, Camera],
    camera_source: str,
    label_source: str,
    class_histogram: dict[str, int],
) -> tuple[Mission, Scene, list[int]]:
    """Add the mission, its files, its registered scene (cameras, label set 1) and the pairs with the
    scenes captured just before and after; return the mission, the scene and the pair ids."""
    mission = Mission(
        site_id=site.id, manifest_sha256=manifest_sha256, name=name, status="ingested", storage=storage,
        root_uri=root_uri,
    )  # fmt: skip
    session.add(mission)
    session.flush()
    for f in files:
        session.add(
            MissionFile(
                mission_id=mission.id, path=f.path, size_bytes=f.size_bytes, sha256=f.sha256, kind=f.kind
            )
        )
    scene = Scene(
        site_id=site.id, mission_id=mission.id, capture_time=capture_time, point_count=point_count,
        bounds=bounds, registration=registration, statistics=statistics, status="registered",
    )  # fmt: skip
    session.add(scene)
    session.flush()
    if cameras:
        add_cameras(session, scene.id, cameras, camera_source)
    session.add(LabelSet(scene_id=scene.id, version=1, source=label_source, class_histogram=class_histogram))
    before, after = neighbours(session, site, capture_time)
    pairs = []
    if before is not None:
        pairs.append(ensure_pair(session, site, before, scene).id)
    if after is not None:
        pairs.append(ensure_pair(session, site, scene, after).id)
    return mission, scene, pairs
