"""Catalog queries on scenes and their cameras, statistics and tilings. Functions take a session;
callers commit."""

from __future__ import annotations

from dataclasses import replace
from datetime import datetime

import numpy as np
import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.camera.pinhole import Camera
from siteline.catalog.addresses import from_record, to_record
from siteline.catalog.models import Camera as CameraRow
from siteline.catalog.models import LabelSet, Mission, Scene, Site
from siteline.catalog.sites import site_name, site_of
from siteline.catalog.stages import add_completed
from siteline.errors import NotFoundError, TileError
from siteline.records.registration import Registration
from siteline.records.release import CameraView, SiteSurvey
from siteline.records.runs import StageRun
from siteline.records.scene import SceneStatistics, SceneView
from siteline.records.site import SiteKey
from siteline.records.tiling import SceneTiling, TileSource


def scene_row(session: Session, scene_id: int) -> Scene:
    """The ORM row of scene ``scene_id`` (for the catalog's own writes); :class:`NotFoundError` naming
    the command that lists scenes when there is none."""
    scene = session.get(Scene, scene_id)
    if scene is None:
        raise NotFoundError(f"no scene with id {scene_id}; see `siteline scene list --site NAME`.")
    return scene


def scene_rows_of(session: Session, site: SiteKey) -> list[Scene]:
    """The ORM rows of the site's scenes in capture order (for the catalog's own writes)."""
    return list(
        session.execute(
            sa.select(Scene).where(Scene.site_id == site.id).order_by(Scene.capture_time)
        ).scalars()
    )


def view_of(scene: Scene) -> SceneView:
    """What the catalog hands out of a scene row."""
    return SceneView(
        scene.id, scene.site_id, scene.mission_id, scene.capture_time, scene.point_count, scene.status,
        scene_registration(scene), scene_statistics(scene), scene.tile_store_uri,
    )  # fmt: skip


def get_scene(session: Session, scene_id: int) -> SceneView:
    """Scene ``scene_id``; :class:`NotFoundError` naming the command that lists scenes when there is none."""
    return view_of(scene_row(session, scene_id))


def list_scenes(session: Session, site: SiteKey) -> list[SceneView]:
    """The site's scenes in capture order."""
    return [view_of(sc) for sc in scene_rows_of(session, site)]


def scene_at(session: Session, site: Site, capture_time: datetime) -> Scene | None:
    return session.execute(
        sa.select(Scene).where(Scene.site_id == site.id, Scene.capture_time == capture_time)
    ).scalar_one_or_none()


def neighbours(session: Session, site: Site, capture_time: datetime) -> tuple[Scene | None, Scene | None]:
    """The site's scenes just before and just after ``capture_time``."""
    before = session.execute(
        sa.select(Scene)
        .where(Scene.site_id == site.id, Scene.capture_time < capture_time)
        .order_by(Scene.capture_time.desc())
        .limit(1)
    ).scalar_one_or_none()
    after = session.execute(
        sa.select(Scene)
        .where(Scene.site_id == site.id, Scene.capture_time > capture_time)
        .order_by(Scene.capture_time)
        .limit(1)
    ).scalar_one_or_none()
    return before, after


def scene_cameras(session: Session, scene_id: int) -> list[tuple[str, Camera]]:
    rows = session.execute(
        sa.select(CameraRow).where(CameraRow.scene_id == scene_id).order_by(CameraRow.image_name)
    ).scalars()
    return [
        (r.image_name, Camera.from_pose(r.width, r.height, r.fx, r.fy, r.cx, r.cy, r.rotation, r.translation))
        for r in rows
    ]


def scene_registration(scene: Scene) -> Registration:
    """The scene's registration record (how its cameras were found, its co-registration)."""
    return Registration.from_dict(scene.registration)


def site_survey(session: Session, site: SiteKey) -> SiteSurvey:
    """The site's registered cameras (size, focal length, height above their scene's lowest point)
    and its sparsest scene's density: what auto release settings are derived from."""
    cameras: list[CameraView] = []
    densities: list[float] = []
    for scene in scene_rows_of(session, site):
        scan = scene_statistics(scene).scan
        if scan is None:
            continue
        densities.append(scan.density_pts_m2)
        ground_z = scan.bounds_min[2]
        cameras += [
            CameraView(scene.id, cam.width, cam.height, cam.fx, float(cam.center[2]) - ground_z)
            for _, cam in scene_cameras(session, scene.id)
        ]
    return SiteSurvey(tuple(cameras), min(densities) if densities else None)


def add_cameras(session: Session, scene_id: int, cameras: dict[str, Camera], source: str) -> None:
    for name, cam in sorted(cameras.items()):
        session.add(
            CameraRow(
                scene_id=scene_id,
                image_name=name,
                width=cam.width,
                height=cam.height,
                fx=cam.fx,
                fy=cam.fy,
                cx=cam.cx,
                cy=cam.cy,
                rotation=list(cam.rotation),
                translation=list(cam.translation),
                source=source,
            )
        )


def site_name_of_scene(session: Session, scene_id: int) -> str:
    """The name of the site of scene ``scene_id``; :class:`NotFoundError` when there is none."""
    return site_name(session, scene_row(session, scene_id).site_id)


def node_summary(scene: Scene) -> dict[str, int]:
    """How ``scene`` is tiled: node index rows, tiles and levels its tiling recorded (0 when untiled)."""
    tiling = scene_statistics(scene).tiling
    if tiling is None or scene.status != "tiled":
        return {"nodes": 0, "tiles": 0, "levels": 0}
    return {"nodes": tiling.nodes, "tiles": tiling.tiles, "levels": tiling.levels}


def mission_of_scene(session: Session, scene_id: int) -> Mission:
    """The mission scene ``scene_id`` was made from."""
    mission = session.get(Mission, scene_row(session, scene_id).mission_id)
    if mission is None:
        raise NotFoundError(f"scene {scene_id} has no mission.")
    return mission


def scene_table(s: Session, site: SiteKey) -> list[dict[str, object]]:
    """The site's scenes in capture order as plain values (for the CLI's list): id, capture time,
    points, status, mission, camera source and the co-registration's translation (m)."""
    rows = []
    for scene in scene_rows_of(s, site):
        reg = scene_registration(scene)
        rows.append({
            "id": scene.id, "capture_time": scene.capture_time, "points": scene.point_count,
            "status": scene.status, "mission_id": scene.mission_id, "registration": reg.source,
            "alignment_m": reg.alignment.translation_m if reg.alignment else None,
        })  # fmt: skip
    return rows


def scene_record(s: Session, scene_id: int) -> dict[str, object]:
    """Scene ``scene_id`` as plain values: statistics, registration, tiles, label sets (for the CLI)."""
    scene = scene_row(s, scene_id)
    nodes = node_summary(scene)
    stats = scene_statistics(scene)
    scan = stats.scan
    return {
        "id": scene.id,
        "site_id": scene.site_id,
        "mission_id": scene.mission_id,
        "capture_time": scene.capture_time,
        "status": scene.status,
        "point_count": scene.point_count,
        "bounds_m": scene.bounds,
        "class_histogram": scan.class_histogram if scan else None,
        "unknown_codes": {str(k): v for k, v in scan.unknown_codes.items()} if scan else None,
        "class_scheme": scan.class_scheme if scan else None,
        "density_pts_m2": scan.density_pts_m2 if scan else None,
        "source_crs": scan.source_crs if scan else None,
        "transformed": scan.transformed if scan else None,
        "z_unit": scan.z_unit.to_dict() if scan and scan.z_unit else None,
        "colour": scan.colour if scan else None,
        "capture_time_source": stats.capture_time_source,
        "registration": (reg := scene_registration(scene)).to_dict(),
        # the co-registration onto the previous scene in words (None for a first scene)
        "alignment": reg.alignment.summary() if reg.alignment else None,
        # how planned cameras were flown, and why at that altitude (None: photo cameras)
        "survey": reg.survey_record(),
        "cameras": len(scene_cameras(s, scene.id)),
        "tile_store": scene.tile_store_uri,
        "tiles": nodes["tiles"],
        "nodes": nodes["nodes"],
        "levels": nodes["levels"],
        "bytes_per_point": stats.tiling.bytes_per_point if stats.tiling else None,
        "label_sets": [
            v
            for (v,) in s.execute(
                sa.select(LabelSet.version).where(LabelSet.scene_id == scene.id).order_by(LabelSet.version)
            )
        ],
    }


def scene_of_mission(session: Session, mission_id: int) -> Scene | None:
    """The scene made from mission ``mission_id``, or None."""
    return session.execute(sa.select(Scene).where(Scene.mission_id == mission_id)).scalar_one_or_none()


def scene_statistics(scene: Scene) -> SceneStatistics:
    """What ingest and tiling recorded about ``scene`` (the one reader of ``scene.statistics``), its
    tile store's address absolute."""
    stats = SceneStatistics.from_json(scene.statistics)
    if stats.tiling is None:
        return stats
    return stats.with_tiling(replace(stats.tiling, uri=from_record(stats.tiling.uri)))


def tile_source(session: Session, scene_id: int) -> TileSource:
    """What a reader needs to open scene ``scene_id``'s tiles; :class:`TileError` naming the command
    when the scene is not tiled."""
    scene = scene_row(session, scene_id)
    tiling = scene_statistics(scene).tiling
    if scene.status != "tiled" or not scene.tile_store_uri or tiling is None:
        raise TileError(f"scene {scene_id} is not tiled yet: run `siteline scene tile {scene_id}`.")
    return TileSource(scene.tile_store_uri, tiling.spec, tiling.checksum)


def record_tiling(
    session: Session, scene_id: int, tiling: SceneTiling, run: StageRun, counts: np.ndarray | None = None
) -> None:
    """Record a tile store that is published whole (its node index inside it): its address, the
    scene's status and tiling statistics, and the stage run; with ``counts`` ((256,) points per class
    id of a re-tiling, whose classes may be mapped anew), the class histogram of the scan and of
    label set 1, which the store holds."""
    scene = scene_row(session, scene_id)
    scene.tile_store_uri = tiling.uri
    scene.status = "tiled"
    stats = scene_statistics(scene).with_tiling(replace(tiling, uri=to_record(tiling.uri)))
    if counts is not None and stats.scan is not None:
        names = {c.id: c.name for c in site_of(session, scene.site_id).taxonomy.classes}
        hist = {names.get(i, str(i)): int(n) for i, n in enumerate(counts) if n}
        stats = replace(stats, scan=replace(stats.scan, class_histogram=hist))
        first = session.execute(
            sa.select(LabelSet).where(LabelSet.scene_id == scene_id, LabelSet.version == 1)
        ).scalar_one_or_none()
        if first is not None:
            first.class_histogram = hist
    scene.statistics = stats.to_json()
    add_completed(session, run)
