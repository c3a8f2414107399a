"""Tiling registered scenes and opening their stores, with the catalog as the index."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

from sqlalchemy.orm import Session

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
from siteline.stores.blobs import resolve_file
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


def store_uri(settings: Settings, scene_id: int, generation: int = 0) -> str:
    """``tiles/scene-<id>.zarr``; a re-tiling (generation g > 0) writes ``scene-<id>-g<g>.zarr`` beside
    it, so the old store stays whole until the new one is committed."""
    name = f"scene-{scene_id}.zarr" if generation == 0 else f"scene-{scene_id}-g{generation}.zarr"
    return settings.store.uri("tiles", name)


def tiling(scene: Scene) -> dict:
    """What tiling recorded in the scene's statistics (spec, checksum, generation, counts); {} before."""
    return (scene.statistics or {}).get("tiles") or {}


def tiling_generation(scene: Scene) -> int:
    """How many times the scene was tiled again (0 until ``--retile``); part of its pairs' output keys."""
    return int(tiling(scene).get("generation", 0))


def tile_checksum(scene: Scene) -> str | None:
    """The checksum of the scene's tile store (its arrays' order is what a label-set store follows)."""
    return tiling(scene).get("checksum")


def layout_hint(scene: Scene) -> str:
    """A sentence for a scene whose store predates the current layout, else ''."""
    doc = tiling(scene).get("spec")
    if doc is None or TileSpec.from_dict(doc).node_order == TileSpec().node_order:
        return ""
    return (
        f" Its store predates shuffled octree nodes, so views read whole levels (up to 4x the points they "
        f"need): `siteline scene tile {scene.id} --retile` tiles it again in the current layout."
    )


def tile_scene(
    catalog: Catalog,
    settings: Settings,
    scene_id: int,
    spec: TileSpec | None = None,
    workers: int = 2,
    progress: Progress | None = None,
    run_id: str | None = None,
    retile: bool = False,
) -> tuple[TileResult | None, str]:
    """Tile a registered scene and index its nodes; a scene already tiled is left alone unless
    ``retile`` (tile it again in the current layout, e.g. a store written before shuffled nodes).

    The store is built locally and published whole (stores.Store.publish); only then are the node
    rows, the store URI and the scene status committed in one transaction. A store without rows (a
    crash between the publish and the commit) is replaced. A re-tiling writes a new store (the next
    generation), commits, then removes the old one: its pairs' outputs are keyed by the generation,
    so they are processed again, and its imported label sets, aligned with the old order, are
    refused until imported again (siteline.labelsets).
    """
    with catalog.transaction() as s:
        scene = s.get(Scene, scene_id)
        if scene is None:
            raise TileError(f"no scene with id {scene_id}.")
        done = scene.status == "tiled" and scene.tile_store_uri and settings.store.is_complete(scene.tile_store_uri)
        if done and not retile:
            return None, (
                f"scene {scene_id} is already tiled at {scene.tile_store_uri}: nothing to do."
                + layout_hint(scene)
            )
        old_uri = scene.tile_store_uri if done else None
        generation = tiling_generation(scene) + 1 if done else tiling_generation(scene)
        from siteline.catalog.models import Site

        site = site_spec(s.get(Site, scene.site_id))
        las = scene_las(s, settings, scene)
        src = parse_crs_or_site((scene.statistics or {}).get("source_crs"), site)
        z_doc = (scene.statistics or {}).get("z_unit")
        z_unit = ZUnit.from_dict(z_doc) if z_doc else None
    spec = spec or TileSpec(tile_size_m=site.tile_size_m)
    out = store_uri(settings, scene_id, generation)
    settings.store.remove(out)
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
                "tiles": result.summary() | {"spec": spec.to_dict(), "generation": generation},
            }
            s.add(
                completed(
                    "tile", f"scene:{scene_id}", {"spec": spec.to_dict(), "workers": workers}, started, run_id
                )
            )
    except BaseException:
        settings.store.remove(out)
        raise
    if old_uri is not None and old_uri != out:
        settings.store.remove(old_uri)
    return (
        result,
        f"scene {scene_id} {'re-tiled' if old_uri else 'tiled'}: {result.points:,} points in "
        f"{result.tiles} tiles, {result.levels} levels, {result.bytes_per_point:.1f} bytes/point",
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
    spec = TileSpec.from_dict(tiling(scene)["spec"])
    return SceneTiles(scene.tile_store_uri, scene_nodes(session, scene.id), spec)
