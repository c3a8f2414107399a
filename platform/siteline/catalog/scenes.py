"""Catalog queries on missions, scenes, cameras and pairs. Functions take a session; callers commit."""

from __future__ import annotations

from dataclasses import replace
from datetime import datetime
from typing import Any

import numpy as np
import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.cameras import Camera
from siteline.catalog.addresses import from_record, to_record
from siteline.catalog.models import Camera as CameraRow
from siteline.catalog.models import LabelSet, Mission, MissionFile, Pair, Scene, Site
from siteline.catalog.sites import site_of
from siteline.catalog.stages import add_completed
from siteline.errors import NotFoundError, TileError
from siteline.records.mission import LasLocation
from siteline.records.release import CameraView, SiteSurvey
from siteline.records.runs import StageRun
from siteline.records.scene import SceneStatistics, SceneSummary
from siteline.records.tiling import SceneTiling, TileSource


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


def list_missions(session: Session, site: Site | None = None) -> list[Mission]:
    q = sa.select(Mission).order_by(Mission.received_at, Mission.id)
    if site is not None:
        q = q.where(Mission.site_id == site.id)
    return list(session.execute(q).scalars())


def get_scene(session: Session, scene_id: int) -> Scene:
    scene = session.get(Scene, scene_id)
    if scene is None:
        raise NotFoundError(f"no scene with id {scene_id}; see `siteline scene list --site NAME`.")
    return scene


def list_scenes(session: Session, site: Site) -> list[Scene]:
    return list(
        session.execute(
            sa.select(Scene).where(Scene.site_id == site.id).order_by(Scene.capture_time)
        ).scalars()
    )


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


def scene_correction(scene: Scene) -> tuple[tuple[float, ...], ...] | None:
    """The co-registration ingest applied to a scene (4 x 4 site-local, previous scene from this one),
    or None when none was applied (siteline.register.check_alignment)."""
    alignment = (scene.registration or {}).get("alignment") or {}
    if not alignment.get("applied"):
        return None
    return tuple(tuple(float(v) for v in row) for row in alignment["correction"])


def site_survey(session: Session, site: Site) -> SiteSurvey:
    """The site's registered cameras (size, focal length, height above their scene's lowest point)
    and its sparsest scene's density: what auto release settings are derived from."""
    cameras: list[CameraView] = []
    densities: list[float] = []
    for scene in list_scenes(session, site):
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


def ensure_pair(session: Session, site: Site, t1: Scene, t2: Scene) -> Pair:
    pair = session.execute(
        sa.select(Pair).where(Pair.t1_scene_id == t1.id, Pair.t2_scene_id == t2.id)
    ).scalar_one_or_none()
    if pair is None:
        pair = Pair(site_id=site.id, t1_scene_id=t1.id, t2_scene_id=t2.id)
        session.add(pair)
        session.flush()
    return pair


def list_pairs(session: Session, site: Site) -> list[Pair]:
    """The site's pairs of consecutive scenes, in capture order (superseded pairs left out)."""
    t1 = sa.orm.aliased(Scene)
    return list(
        session.execute(
            sa.select(Pair)
            .join(t1, Pair.t1_scene_id == t1.id)
            .where(Pair.site_id == site.id, Pair.status != "superseded")
            .order_by(t1.capture_time)
        ).scalars()
    )


def supersede_pair(session: Session, t1_id: int, t2_id: int) -> None:
    """Mark the pair (t1, t2) superseded: a scene captured between them arrived later. Its outputs and
    the releases that used it stay; new releases draw on the consecutive pairs."""
    session.execute(
        sa.update(Pair)
        .where(Pair.t1_scene_id == t1_id, Pair.t2_scene_id == t2_id)
        .values(status="superseded")
    )


def pair_ids_of_scene(session: Session, scene_id: int) -> list[int]:
    """Ids of the pairs ``scene_id`` belongs to (as t1 or t2), ascending."""
    return list(
        session.execute(
            sa.select(Pair.id)
            .where(
                (Pair.t1_scene_id == scene_id) | (Pair.t2_scene_id == scene_id), Pair.status != "superseded"
            )
            .order_by(Pair.id)
        ).scalars()
    )


def site_name_of_scene(session: Session, scene_id: int) -> str:
    """The name of the site of scene ``scene_id``; :class:`NotFoundError` when there is none."""
    return _site_name(session, get_scene(session, scene_id).site_id)


def _site_name(session: Session, site_id: int) -> str:
    site = session.get(Site, site_id)
    if site is None:
        raise NotFoundError(f"no site with id {site_id}.")
    return site.name


def site_name_of_pair(session: Session, pair_id: int) -> str:
    """The name of the site of pair ``pair_id``; :class:`NotFoundError` when there is none."""
    pair = session.get(Pair, pair_id)
    if pair is None:
        raise NotFoundError(f"no pair with id {pair_id}.")
    return _site_name(session, pair.site_id)


def node_summary(scene: Scene) -> dict[str, int]:
    """How ``scene`` is tiled: node index rows, tiles and levels its tiling recorded (0 when untiled)."""
    tiling = scene_statistics(scene).tiling
    if tiling is None or scene.status != "tiled":
        return {"nodes": 0, "tiles": 0, "levels": 0}
    return {"nodes": tiling.nodes, "tiles": tiling.tiles, "levels": tiling.levels}


def mission_of_scene(session: Session, scene_id: int) -> Mission:
    """The mission scene ``scene_id`` was made from."""
    mission = session.get(Mission, get_scene(session, scene_id).mission_id)
    if mission is None:
        raise NotFoundError(f"scene {scene_id} has no mission.")
    return mission


def scene_record(s: Session, scene_id: int) -> dict[str, Any]:
    """Scene ``scene_id`` as plain values: statistics, registration, tiles, label sets (for the CLI)."""
    scene = get_scene(s, scene_id)
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
        "z_unit": scan.z_unit if scan else None,
        "colour": scan.colour if scan else None,
        "capture_time_source": stats.capture_time_source,
        "registration": scene.registration,
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


def blobs_in_use(session: Session, shas: list[str]) -> set[str]:
    """Which of ``shas`` the catalog references (blobs another ingest committed): a mission's file or a
    scene's alignment sample."""
    if not shas:
        return set()
    files = session.execute(sa.select(MissionFile.sha256).where(MissionFile.sha256.in_(shas))).scalars()
    sample = Scene.statistics["stable_sample_sha256"].as_string()
    return set(files) | set(session.execute(sa.select(sample).where(sample.in_(shas))).scalars())


def lock_site(session: Session, site_id: int) -> Site:
    """The site row, locked for the rest of the transaction (one registration per site at a time)."""
    return session.execute(sa.select(Site).where(Site.id == site_id).with_for_update()).scalar_one()


def mission_file(session: Session, mission_id: int, path: str | None) -> MissionFile | None:
    """The file ``path`` of mission ``mission_id``, or None."""
    return session.execute(
        sa.select(MissionFile).where(MissionFile.mission_id == mission_id, MissionFile.path == path)
    ).scalar_one_or_none()


def scene_statistics(scene: Scene) -> SceneStatistics:
    """What ingest and tiling recorded about ``scene`` (the one reader of ``scene.statistics``), its
    tile store's address absolute."""
    stats = SceneStatistics.from_json(scene.statistics)
    if stats.tiling is None:
        return stats
    return stats.with_tiling(replace(stats.tiling, uri=from_record(stats.tiling.uri)))


def scene_summaries(session: Session, site: Site) -> tuple[SceneSummary, ...]:
    """The site's scenes in capture order, as records."""
    return tuple(
        SceneSummary(sc.id, sc.capture_time, sc.status, scene_statistics(sc))
        for sc in list_scenes(session, site)
    )


def tile_source(session: Session, scene_id: int) -> TileSource:
    """What a reader needs to open scene ``scene_id``'s tiles; :class:`TileError` naming the command
    when the scene is not tiled."""
    scene = get_scene(session, scene_id)
    tiling = scene_statistics(scene).tiling
    if scene.status != "tiled" or not scene.tile_store_uri or tiling is None:
        raise TileError(f"scene {scene_id} is not tiled yet: run `siteline scene tile {scene_id}`.")
    return TileSource(scene.tile_store_uri, tiling.spec, tiling.checksum)


def las_location(session: Session, scene_id: int) -> LasLocation:
    """Where scene ``scene_id``'s point cloud is kept; :class:`TileError` when its mission records none."""
    scene = get_scene(session, scene_id)
    stats = scene_statistics(scene)
    mission = session.get(Mission, scene.mission_id)
    row = mission_file(session, scene.mission_id, stats.las_file)
    if mission is None or row is None:
        raise TileError(f"scene {scene_id}: its mission records no point cloud file.")
    return LasLocation(mission.storage, mission.root_uri, row.path, row.sha256)  # type: ignore[arg-type]


def record_tiling(
    session: Session, scene_id: int, tiling: SceneTiling, run: StageRun, counts: np.ndarray | None = None
) -> None:
    """Record a tile store that is published whole (its node index inside it): its address, the
    scene's status and tiling statistics, and the stage run; with ``counts`` ((256,) points per class
    id of a re-tiling, whose classes may be mapped anew), the class histogram of the scan and of
    label set 1, which the store holds."""
    scene = get_scene(session, scene_id)
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


def needs_tiling(session: Session, scene_id: int) -> bool:
    """Whether the scene is not tiled, or was tiled under an earlier version of its site."""
    scene = get_scene(session, scene_id)
    tiling = scene_statistics(scene).tiling
    site = session.get(Site, scene.site_id)
    if scene.status != "tiled" or tiling is None or site is None:
        return True
    return tiling.site_version != (site.version or 1)


def scene_ids_of_pairs(session: Session, pair_ids: list[int]) -> list[int]:
    """The scenes the pairs ``pair_ids`` join, each once, in pair order (unknown pairs are skipped)."""
    out: list[int] = []
    for pid in pair_ids:
        pair = session.get(Pair, pid)
        if pair is not None:
            out += [sid for sid in (pair.t1_scene_id, pair.t2_scene_id) if sid not in out]
    return out
