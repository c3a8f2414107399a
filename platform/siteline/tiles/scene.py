"""Tiling registered scenes and opening their stores, with the catalog as the index."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

from sqlalchemy.orm import Session

from siteline import stores
from siteline.catalog import Catalog
from siteline.catalog.models import Mission, Scene
from siteline.catalog.scenes import mission_file, node_rows, replace_nodes
from siteline.catalog.sites import site_spec
from siteline.catalog.stages import completed
from siteline.config import Settings
from siteline.crs import ZUnit, parse_source_crs
from siteline.errors import TileError
from siteline.progress import Progress
from siteline.site import SiteSpec
from siteline.stores import resolve_file
from siteline.tiles.layout import TileSpec
from siteline.tiles.reader import SceneTiles
from siteline.tiles.writer import NodeInfo, TileResult, write_tiles


def scene_las(session: Session, settings: Settings, scene: Scene) -> Path:
    """Where the scene's LAS/LAZ bytes are (the store's blob, or the referenced original)."""
    stats = scene.statistics or {}
    mission = session.get(Mission, scene.mission_id)
    row = mission_file(session, mission.id, stats.get("las_file"))
    if row is None:
        raise TileError(f"scene {scene.id}: its mission records no point cloud file.")
    path = resolve_file(settings.store, mission.storage, mission.root_uri, row.path, row.sha256)
    if not path.is_file():
        where = (
            "the store"
            if mission.storage == "copy"
            else "its mission folder (a referenced mission must stay on a path every worker sees)"
        )
        raise TileError(f"scene {scene.id}: point cloud {path} is missing from {where}.")
    return path


def store_uri(settings: Settings, scene_id: int) -> str:
    return settings.store.uri("tiles", f"scene-{scene_id}.zarr")


def tile_scene(
    catalog: Catalog,
    settings: Settings,
    scene_id: int,
    spec: TileSpec | None = None,
    workers: int = 2,
    progress: Progress | None = None,
    run_id: str | None = None,
) -> tuple[TileResult | None, str]:
    """Tile a registered scene and index its nodes; a scene already tiled is left alone.

    The store is built locally and published whole (stores.Store.publish); only then are the node
    rows, the store URI and the scene status committed in one transaction. A store without rows (a
    crash between the publish and the commit) is replaced.
    """
    with catalog.transaction() as s:
        scene = s.get(Scene, scene_id)
        if scene is None:
            raise TileError(f"no scene with id {scene_id}.")
        if scene.status == "tiled" and scene.tile_store_uri and stores.is_complete(scene.tile_store_uri):
            return None, f"scene {scene_id} is already tiled at {scene.tile_store_uri}: nothing to do."
        from siteline.catalog.models import Site

        site = site_spec(s.get(Site, scene.site_id))
        las = scene_las(s, settings, scene)
        src = parse_crs_or_site((scene.statistics or {}).get("source_crs"), site)
        z_doc = (scene.statistics or {}).get("z_unit")
        z_unit = ZUnit.from_dict(z_doc) if z_doc else None
    spec = spec or TileSpec(tile_size_m=site.tile_size_m)
    out = store_uri(settings, scene_id)
    stores.remove(out)
    started = datetime.now(UTC)
    with settings.store.publish(out) as work:
        result = write_tiles(
            las, site, src, work, spec, workers=workers, seed=scene_id, progress=progress, z_unit=z_unit
        )
    result.uri = out
    try:
        with catalog.transaction() as s:
            scene = s.get(Scene, scene_id)
            replace_nodes(
                s,
                scene_id,
                [
                    {
                        "key": n.key,
                        "tile": n.tile,
                        "level": n.level,
                        "bounds_min": n.bounds_min,
                        "bounds_max": n.bounds_max,
                        "count": n.count,
                        "start": n.start,
                        "spacing_m": n.spacing_m,
                        "cell": n.cell,
                    }
                    for n in result.nodes
                ],  # fmt: skip
            )
            scene.tile_store_uri = result.uri
            scene.status = "tiled"
            scene.statistics = {
                **(scene.statistics or {}),
                "tiles": result.summary() | {"spec": spec.to_dict()},
            }
            s.add(
                completed(
                    "tile", f"scene:{scene_id}", {"spec": spec.to_dict(), "workers": workers}, started, run_id
                )
            )
    except BaseException:
        stores.remove(out)
        raise
    return (
        result,
        f"scene {scene_id} tiled: {result.points:,} points in {result.tiles} tiles, {result.levels} levels, "
        f"{result.bytes_per_point:.1f} bytes/point",
    )


def parse_crs_or_site(text: str | None, site: SiteSpec):  # noqa: ANN201
    """The source CRS recorded at ingest (EPSG code or WKT), or the site's when none was recorded."""
    return parse_source_crs(text) if text else site.pyproj_crs


def scene_nodes(session: Session, scene_id: int) -> list[NodeInfo]:
    rows = node_rows(session, scene_id)
    return [
        NodeInfo(
            r.key,
            r.tile,
            r.level,
            (r.min_x, r.min_y, r.min_z),
            (r.max_x, r.max_y, r.max_z),
            r.point_count,
            r.start,
            r.spacing_m,
            None if r.cell_x is None else (r.cell_x, r.cell_y, r.cell_z),
        )
        for r in rows
    ]


def open_scene_tiles(session: Session, scene: Scene) -> SceneTiles:
    """The scene's tile store, indexed by its catalog node rows."""
    if scene.status != "tiled" or not scene.tile_store_uri:
        raise TileError(f"scene {scene.id} is not tiled yet: run `siteline scene tile {scene.id}`.")
    spec = TileSpec.from_dict(scene.statistics["tiles"]["spec"])
    return SceneTiles(scene.tile_store_uri, scene_nodes(session, scene.id), spec)
