"""Prefect flows of siteline: thin orchestration over ``siteline.pipeline``, passing ids and paths only.

Chain: an upload event (``siteline.mission.uploaded``, from ``siteline watch`` or POST /api/events)
triggers ``ingest-mission``; it registers and tiles the scene and emits ``siteline.scene.registered``,
which triggers ``process-scene-pairs``; with ``SITELINE_RELEASE_POLICY=every-pair`` that flow then builds
and publishes a release (``on-demand``: run ``build-release`` yourself). ``siteline labels import``
posts ``siteline.labels.imported`` once a corrected label set is recorded; it triggers
``process-scene-pairs`` for that scene too, which processes its pairs with the newest label sets (new
outputs beside the old) and applies the same release policy.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from prefect import flow, get_run_logger, tags, task
from prefect.artifacts import (
    create_markdown_artifact,
    create_progress_artifact,
    create_table_artifact,
    update_progress_artifact,
)
from prefect.cache_policies import NO_CACHE
from prefect.events import emit_event
from prefect.runtime import flow_run

sys.path.insert(0, str(Path(__file__).resolve().parent))
from runner import task_runner  # noqa: E402

from siteline import pipeline  # noqa: E402
from siteline.catalog import Catalog, open_catalog  # noqa: E402
from siteline.catalog.scenes import pair_ids_of_scene, site_name_of_pair, site_name_of_scene  # noqa: E402
from siteline.catalog.stages import record_failure  # noqa: E402
from siteline.config import Settings, load_settings  # noqa: E402
from siteline.errors import SitelineError, StoreError  # noqa: E402
from siteline.ingest import IngestOptions  # noqa: E402
from siteline.pairs import PairParams  # noqa: E402
from siteline.records.runs import StageRun  # noqa: E402
from siteline.stores import join  # noqa: E402

T = TypeVar("T")


def artifact_key(*parts: Any) -> str:
    """Artifact keys: lowercase letters, digits and dashes."""
    return re.sub(r"[^a-z0-9-]+", "-", "-".join(str(p) for p in parts).lower()).strip("-")[:100]


def transient(task: Any, task_run: Any, state: Any) -> bool:
    """Retry I/O only: store errors, OS and network errors, a lost database connection. Never bad
    input (a SitelineError says what to fix) and never a programming error (it would fail again)."""
    import sqlalchemy as sa

    try:
        state.result()
    except StoreError:
        return True
    except SitelineError:
        return False
    except (OSError, TimeoutError, ConnectionError):
        return True
    except sa.exc.DBAPIError as exc:
        return bool(exc.connection_invalidated) or isinstance(exc, sa.exc.OperationalError)
    except Exception:
        return False
    return False


def _run_id() -> str | None:
    rid = flow_run.id
    return str(rid) if rid else None


@contextmanager
def _catalog() -> Iterator[tuple[Catalog, Settings]]:
    settings = load_settings()
    cat = open_catalog(settings)
    try:
        yield cat, settings
    finally:
        cat.dispose()


def _stage(
    stage: str, subject: str, params: dict[str, Any], fn: Callable[..., T], *args: Any, **kwargs: Any
) -> T:
    """Run a pipeline step; on failure record it in the catalog (its own transaction) and re-raise."""
    with _catalog() as (cat, settings):
        try:
            return fn(cat, settings, *args, run_id=_run_id(), **kwargs)
        except Exception as exc:
            with cat.transaction() as s:
                record_failure(s, StageRun(stage, subject, params, run_id=_run_id()), exc)
            raise


def _read(fn: Callable[..., T], *args: Any) -> T:
    """One catalog read function (siteline.catalog) in its own transaction."""
    with _catalog() as (cat, _), cat.transaction() as s:
        return fn(s, *args)


@task(retries=2, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def ingest_task(mission_dir: str, site: str, crs: str | None, accept_misalignment: bool) -> dict[str, Any]:
    opts = IngestOptions(crs=crs, accept_misalignment=accept_misalignment)
    done = _stage(
        "ingest",
        f"mission:{mission_dir}",
        {"site": site, "crs": crs},
        pipeline.ingest,
        Path(mission_dir),
        site,
        opts,
    )
    tiling = done.tiles.tiling if done.tiles is not None else None
    return done.ingest.to_dict() | {"tiles": tiling.to_dict() if tiling is not None else None}


@task(retries=2, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def tile_task(scene_id: int) -> dict[str, Any] | None:
    done = _stage("tile", f"scene:{scene_id}", {}, pipeline.tile_scenes, [scene_id])
    for outcome in done:
        get_run_logger().info(outcome.message)
    tiling = done[0].tiling if done else None
    return tiling.to_dict() if tiling is not None else None


@task(retries=2, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def process_pair_task(pair_id: int, params: dict[str, Any] | None, site: str) -> dict[str, Any]:
    p = PairParams.from_dict(params) if params else PairParams()
    key = artifact_key("progress", site, "pair", pair_id)
    progress_id = create_progress_artifact(0.0, key=key, description=f"renders of pair {pair_id}")
    done = {"n": 0}

    def report(task_name: str, n: int, total: int | None) -> None:
        if task_name == "renders" and total:
            done["n"] += n
            update_progress_artifact(progress_id, 100.0 * done["n"] / total)

    outs = _stage(
        "process_pair", f"pair:{pair_id}", p.to_dict(), pipeline.process_pairs, [pair_id], p, progress=report
    )
    out = outs[pair_id]
    update_progress_artifact(progress_id, 100.0)
    return {
        "pair": out.pair_id,
        "t1": out.t1,
        "t2": out.t2,
        "radius_m": out.radius_m,
        "views": out.view_count,
        "root": out.root,
        "labels": out.labels.get("counts"),
        "samples": [
            {
                "view": v.index,
                "strategy": v.strategy,
                "change_ratio": v.change_ratio,
                "a": join(out.root, "A", v.file),
                "mask": join(out.root, "label", v.file),
            }
            for v in out.views[:6]
        ],
    }


@task(retries=1, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def build_release_task(site: str, name: str, params: dict[str, Any] | None, publish: bool) -> dict[str, Any]:
    p = PairParams.from_dict(params) if params else PairParams()
    info = _stage(
        "build_release", f"release:{name}", p.to_dict(), pipeline.release, site, name, p, publish=publish
    )
    return info.to_dict()


def _tag_run(*extra: str) -> None:
    """Tag the running flow run (tags given at run creation are fixed; these come from parameters)."""
    from prefect.client.orchestration import get_client

    rid = flow_run.id
    if not rid:
        return
    with get_client(sync_client=True) as client:
        run = client.read_flow_run(rid)
        client.update_flow_run(rid, tags=sorted(set(run.tags) | set(extra)))


def ingest_run_name() -> str:
    return f"ingest-{Path(flow_run.parameters['mission_dir']).name}"


def _ingest_dashboards(site: str, mission: str, res: dict[str, Any]) -> None:
    rows = {
        "mission": mission, "manifest_sha256": res["manifest_sha256"], "files": res["files"],
        "created": res["created"], "message": res["message"],
    }  # fmt: skip
    create_table_artifact(
        [{"item": k, "value": str(v)} for k, v in rows.items()],
        key=artifact_key("mission", site, mission),
        description=f"mission inventory of {mission}",
    )
    scan, tiles = res.get("scan") or {}, res.get("tiles") or {}
    if not scan:
        return
    stats = {
        "points": scan.get("point_count"), "density_pts_m2": round(scan.get("density_pts_m2", 0), 2),
        "classes": scan.get("class_histogram"), "unknown_codes": scan.get("unknown_codes"),
        "registration": res["registration"].get("source"), "rms_m": res["registration"].get("rms_m"),
        "alignment_m": (res["registration"].get("alignment") or {}).get("translation_m"),
        "tiles": tiles.get("tiles"), "bytes_per_point": tiles.get("bytes_per_point"),
    }  # fmt: skip
    create_table_artifact(
        [{"statistic": k, "value": str(v)} for k, v in stats.items()],
        key=artifact_key("scene", site, res["scene_id"]),
        description=f"scene {res['scene_id']} statistics",
    )


@flow(name="ingest-mission", flow_run_name=ingest_run_name, task_runner=task_runner(), log_prints=True)
def ingest_mission_flow(
    mission_dir: str, site: str, crs: str | None = None, accept_misalignment: bool = False
) -> int | None:
    """Ingest an uploaded mission, tile its scene, publish dashboards, announce the scene."""
    _tag_run(f"site:{site}")
    with tags(f"site:{site}"):
        # in the flow's own process: the upload folder is on this machine, not on the runner's workers
        res = ingest_task(mission_dir, site, crs, accept_misalignment)
        _ingest_dashboards(site, Path(mission_dir).name, res)
        if res["scene_id"] is None:
            return None
        emit_event(
            "siteline.scene.registered",
            resource={"prefect.resource.id": f"siteline.scene.{res['scene_id']}", "siteline.site": site},
            payload={"scene_id": res["scene_id"], "site": site, "pairs": res["pairs"]},
        )
        return res["scene_id"]


@flow(name="tile-scene", flow_run_name="tile-scene-{scene_id}", task_runner=task_runner())
def tile_scene_flow(scene_id: int) -> dict[str, Any] | None:
    _tag_run(f"site:{_read(site_name_of_scene, scene_id)}")
    return tile_task.submit(scene_id).result()


@flow(name="process-pair", flow_run_name="process-pair-{pair_id}", task_runner=task_runner())
def process_pair_flow(pair_id: int, params: dict[str, Any] | None = None) -> dict[str, Any]:
    out = process_pair_task.submit(pair_id, params, _read(site_name_of_pair, pair_id)).result()
    _pair_dashboards(out)
    return out


def _pair_dashboards(out: dict[str, Any]) -> None:
    site = _read(site_name_of_scene, out["t2"])
    create_table_artifact(
        [{k: out[k] for k in ("pair", "t1", "t2", "radius_m", "views")} | {"labels": str(out["labels"])}],
        key=artifact_key("pair", site, out["pair"]),
        description=f"pair {out['pair']} summary",
    )
    lines = [
        f"# Pair {out['pair']} (scenes {out['t1']} -> {out['t2']})",
        "",
        "| view | strategy | change ratio | t1 | mask |",
        "|---|---|---|---|---|",
    ]
    lines += [
        f"| {s['view']} | {s['strategy']} | {s['change_ratio']:.3f} | `{s['a']}` | `{s['mask']}` |"
        for s in out["samples"]
    ]
    create_markdown_artifact(
        "\n".join(lines),
        key=artifact_key("renders", site, out["pair"]),
        description=f"sample renders of pair {out['pair']}",
    )


@flow(name="build-release", flow_run_name="build-release-{name}", task_runner=task_runner())
def build_release_flow(
    site: str, name: str, params: dict[str, Any] | None = None, publish: bool = True
) -> dict[str, Any]:
    _tag_run(f"site:{site}")
    info = build_release_task(site, name, params, publish)
    stats = info.get("stats") or {}
    create_table_artifact(
        [{"split": k, **v} for k, v in (stats.get("class_balance") or {}).items()],
        key=artifact_key("release", site, name, info["version"]),
        description=f"release {name} {info['version']} ({info['status']}) at {info['root']}",
    )
    return info


@flow(name="process-scene-pairs", flow_run_name="process-scene-{scene_id}", task_runner=task_runner())
def process_scene_pairs_flow(
    scene_id: int, params: dict[str, Any] | None = None, release_name: str | None = None
) -> list[dict[str, Any]]:
    """Process every pair the scene belongs to (a new scene, or a scene with a new label-set version:
    each scene's newest label set is used); then apply the release policy."""
    site = _read(site_name_of_scene, scene_id)
    _tag_run(f"site:{site}")
    settings = load_settings()
    pair_ids = _read(pair_ids_of_scene, scene_id)
    with tags(f"site:{site}"):
        futures = [process_pair_task.submit(pid, params, site) for pid in pair_ids]
        outs = [f.result() for f in futures]
    for out in outs:
        _pair_dashboards(out)
    if outs and settings.release_policy == "every-pair":
        build_release_flow(site, release_name or settings.release_name or f"{site}-cd", params, True)
    return outs
