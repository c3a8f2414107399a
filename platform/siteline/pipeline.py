"""The pipeline's order, written once (DESIGN.md §1): ingest -> tile -> process pairs -> build release
-> publish. The CLI, the demo, the flows and the tests call these; each stage function below it does
only its own stage and refuses, naming the command, when a precondition is missing. No Prefect here.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from siteline.catalog import Catalog
from siteline.catalog.scenes import get_scene, scene_ids_of_pairs
from siteline.config import Settings
from siteline.ingest.mission import IngestOptions, IngestResult, ingest_mission
from siteline.pairs import PairOutput, PairParams, process_pair
from siteline.progress import Progress
from siteline.release.build import ReleaseInfo, build_release, choose_pairs, publish_release
from siteline.tiles import TileResult, tile_scene


def ingest(
    catalog: Catalog,
    settings: Settings,
    mission_dir: Path,
    site: str,
    opts: IngestOptions | None = None,
    workers: int = 2,
    progress: Progress | None = None,
    run_id: str | None = None,
) -> tuple[IngestResult, TileResult | None]:
    """Ingest ``mission_dir`` as a scene of ``site`` and tile it (``progress`` follows both). A mission
    already ingested is not ingested again; its scene is tiled if it is not yet."""
    result = ingest_mission(catalog, settings, Path(mission_dir), site, opts, progress, run_id=run_id)
    tiled = None
    if result.scene_id is not None:
        tiled, message = tile_scene(
            catalog, settings, result.scene_id, workers=workers, progress=progress, run_id=run_id
        )
        if tiled is not None:
            result.message += f"; {message}"
    return result, tiled


def tile_scenes(
    catalog: Catalog,
    settings: Settings,
    scene_ids: Iterable[int],
    workers: int = 2,
    progress: Progress | None = None,
    run_id: str | None = None,
) -> list[str]:
    """Tile every scene of ``scene_ids`` that is not tiled yet; one message per scene."""
    messages = []
    for sid in scene_ids:
        with catalog.transaction() as s:
            tiled = get_scene(s, sid).status == "tiled"
        if not tiled:
            messages.append(
                tile_scene(catalog, settings, sid, workers=workers, progress=progress, run_id=run_id)[1]
            )
    return messages


def process_pairs(
    catalog: Catalog,
    settings: Settings,
    pair_ids: Iterable[int],
    params: PairParams | None = None,
    progress: Progress | None = None,
    device: str = "cpu",
    run_id: str | None = None,
    label_sets: dict[int, int] | None = None,
) -> dict[int, PairOutput]:
    """Tile the pairs' scenes where needed, then process every pair (outputs are reused when made)
    with each scene's newest label set, or the version ``label_sets`` (scene id -> version) pins."""
    params = params or PairParams()
    ids = list(pair_ids)
    with catalog.transaction() as s:
        scene_ids = scene_ids_of_pairs(s, ids)
    tile_scenes(catalog, settings, scene_ids, progress=progress, run_id=run_id)
    return {
        pid: process_pair(
            catalog,
            settings,
            pid,
            params,
            progress=progress,
            device=device,
            run_id=run_id,
            label_sets=label_sets,
        )
        for pid in ids
    }


def release(
    catalog: Catalog,
    settings: Settings,
    site: str,
    name: str,
    params: PairParams | None = None,
    pair_ids: list[int] | None = None,
    version: str | None = None,
    preset: str | None = None,
    publish: bool = False,
    progress: Progress | None = None,
    device: str = "cpu",
    pad: bool = True,
    run_id: str | None = None,
    label_sets: dict[int, int] | None = None,
) -> ReleaseInfo:
    """Everything a release of ``site`` needs, in order: the pairs (``pair_ids`` or all) processed
    with ``params`` (after ``preset``) on each scene's newest label set (or the version
    ``label_sets`` pins), a draft built from them, and published when ``publish``."""
    params = params or PairParams()
    if preset is not None:
        from siteline.presets import preset_params

        params = preset_params(preset, params)
    with catalog.transaction() as s:
        chosen = choose_pairs(s, site, pair_ids)
    outputs = process_pairs(
        catalog,
        settings,
        chosen,
        params,
        progress=progress,
        device=device,
        run_id=run_id,
        label_sets=label_sets,
    )
    info = build_release(
        catalog,
        settings,
        site,
        name,
        params,
        chosen,
        version,
        preset,
        run_id=run_id,
        pad=pad,
        outputs=outputs,
        label_sets=label_sets,
    )
    if publish:
        info = publish_release(catalog, settings, name, info.version, run_id=run_id)
    return info
