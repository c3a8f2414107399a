"""The pipeline's order, written once (DESIGN.md §1): ingest -> tile -> process pairs -> build release
-> publish. The CLI, the demo, the flows and the tests call these; each stage function below it does
only its own stage (plan -> execute -> record) and refuses, naming the command, when a precondition
is missing. No Prefect here."""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path

from siteline.catalog import Catalog
from siteline.catalog.pairs import unprocessed_pairs
from siteline.catalog.scenes import get_scene, pair_ids_of_scene, scene_ids_of_pairs
from siteline.config import Settings
from siteline.ingest import IngestOptions, IngestResult, ingest_mission
from siteline.pairs.params import PairParams
from siteline.pairs.stage import process_pair
from siteline.progress import Progress, no_progress
from siteline.records.pairs import PairOutput
from siteline.records.release import ReleaseInfo
from siteline.release.knobs import ReleaseKnobs
from siteline.release.params import ReleaseParams
from siteline.release.plan import (
    check_release_name,
    check_view_count,
    choose_pairs,
    pair_camera_counts,
    release_params,
    semver,
)
from siteline.release.stage import build_release
from siteline.tiles import TileOutcome, tile_scene

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Ingested:
    """An ingest and the tiling of its scene (None when the mission made no new scene to tile)."""

    ingest: IngestResult
    tiles: TileOutcome | None


def ingest(
    catalog: Catalog,
    settings: Settings,
    mission_dir: Path,
    site: str,
    opts: IngestOptions | None = None,
    workers: int = 2,
    progress: Progress = no_progress,
    run_id: str | None = None,
) -> Ingested:
    """Ingest ``mission_dir`` as a scene of ``site`` and tile it. A mission already ingested is not
    ingested again; its scene is tiled if it is not yet."""
    result = ingest_mission(
        catalog, settings, Path(mission_dir), site, opts, progress, run_id=run_id, workers=workers
    )
    if result.scene_id is None:
        return Ingested(result, None)
    tiled = tile_scene(catalog, settings, result.scene_id, workers=workers, progress=progress, run_id=run_id)
    if tiled.tiling is not None:
        result.message += f"; {tiled.message}"
    return Ingested(result, tiled)


def tile_scenes(
    catalog: Catalog,
    settings: Settings,
    scene_ids: Iterable[int],
    workers: int = 2,
    progress: Progress = no_progress,
    run_id: str | None = None,
    executor: Executor | None = None,
) -> list[TileOutcome]:
    """Tile every scene of ``scene_ids`` that is not tiled yet (its tiles written by ``executor``, a
    Dask cluster's say, when given)."""
    done = []
    for sid in scene_ids:
        with catalog.transaction() as s:
            tiled = get_scene(s, sid).status == "tiled"
        if not tiled:
            done.append(
                tile_scene(
                    catalog,
                    settings,
                    sid,
                    workers=workers,
                    progress=progress,
                    run_id=run_id,
                    executor=executor,
                )
            )
    return done


def process_pairs(
    catalog: Catalog,
    settings: Settings,
    pair_ids: Iterable[int],
    params: PairParams | None = None,
    progress: Progress = no_progress,
    device: str = "cpu",
    run_id: str | None = None,
    label_sets: Mapping[int, int] | None = None,
) -> dict[int, PairOutput]:
    """Tile the pairs' scenes where needed, then process every pair (outputs are reused when made)
    with each scene's newest label set, or the version ``label_sets`` (scene id -> version) pins."""
    ids = list(pair_ids)
    with catalog.transaction() as s:
        scene_ids = scene_ids_of_pairs(s, ids)
    tile_scenes(catalog, settings, scene_ids, progress=progress, run_id=run_id)
    return {
        pid: process_pair(catalog, settings, pid, params, progress, device, run_id, label_sets) for pid in ids
    }


def pending_pairs(catalog: Catalog, scene_id: int) -> list[int]:
    """The pairs of ``scene_id`` nobody processed yet (no outputs under any parameters): whether a
    mission ingested again still has work to announce."""
    with catalog.transaction() as s:
        return unprocessed_pairs(s, pair_ids_of_scene(s, scene_id))


def release_parameters(catalog: Catalog, site: str, knobs: ReleaseKnobs | None = None) -> ReleaseParams:
    """What a release of ``site`` built now would use: its release settings with ``knobs`` over them,
    auto knobs worked out (refused when its images would be too small)."""
    with catalog.transaction() as s:
        return release_params(s, site, knobs, f"a release of site {site}")


def release(
    catalog: Catalog,
    settings: Settings,
    site: str,
    name: str,
    knobs: ReleaseKnobs | None = None,
    pair_ids: Sequence[int] | None = None,
    version: str | None = None,
    publish: bool = False,
    progress: Progress = no_progress,
    device: str = "cpu",
    run_id: str | None = None,
    label_sets: Mapping[int, int] | None = None,
) -> ReleaseInfo:
    """Everything a release of ``site`` needs, in order: its parameters (the site's release settings
    with ``knobs`` over them, siteline.release.knobs: refused before any work when its images would be
    too small), the pairs (``pair_ids`` or all) processed on each scene's newest label set (or the
    version ``label_sets`` pins), a draft built from exactly those outputs, published when
    ``publish``; or the latest version when it already has these inputs (``up_to_date``)."""
    check_release_name(name)  # refused before any pair is processed
    if version is not None:
        semver(version)
    with catalog.transaction() as s:
        params = release_params(s, site, knobs, f"release {name}")
        chosen = choose_pairs(s, site, pair_ids)
        check_view_count(pair_camera_counts(s, chosen), params.pair, f"release {name}")
    log.info("release %s of site %s: %d pairs, scale %g, %d px points, %d views", name, site, len(chosen),
             params.pair.scale, params.pair.point_size_px, params.pair.views)  # fmt: skip
    outputs = process_pairs(catalog, settings, chosen, params.pair, progress, device, run_id, label_sets)
    # build on the label sets the outputs used, even if a newer one was imported meanwhile
    used = {
        sid: v
        for out in outputs.values()
        for sid, v in ((out.t1, out.versions.t1), (out.t2, out.versions.t2))
    }
    return build_release(
        catalog, settings, site, name, params, chosen, version, run_id, used, publish, progress
    )
