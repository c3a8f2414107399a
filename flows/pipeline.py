"""Prefect flows of siteline: thin orchestration over library calls, passing ids and paths only.

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
from pathlib import Path
from typing import Any

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

from siteline.catalog import open_catalog  # noqa: E402
from siteline.catalog.scenes import (  # noqa: E402
    pair_ids_of_scene,
    site_name_of_pair,
    site_name_of_scene,
)
from siteline.catalog.stages import record_failure  # noqa: E402
from siteline.config import load_settings  # noqa: E402
from siteline.errors import SitelineError, StoreError  # noqa: E402
from siteline.stores import join  # noqa: E402


def artifact_key(*parts: Any) -> str:
    """Artifact keys: lowercase letters, digits and dashes."""
    return re.sub(r"[^a-z0-9-]+", "-", "-".join(str(p) for p in parts).lower()).strip("-")[:100]


def transient(task, task_run, state) -> bool:  # noqa: ANN001
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


def _stage(stage: str, subject: str, params: dict, fn, *args, **kwargs):  # noqa: ANN001, ANN202
    """Run a library stage; on failure record it in the catalog (its own transaction) and re-raise."""
    settings = load_settings()
    cat = open_catalog(settings)
    try:
        return fn(cat, settings, *args, run_id=_run_id(), **kwargs)
    except Exception as exc:
        with cat.transaction() as s:
            record_failure(s, stage, subject, params, exc, run_id=_run_id())
        raise
    finally:
        cat.dispose()


@task(retries=2, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def ingest_task(mission_dir: str, site: str, crs: str | None, accept_misalignment: bool) -> dict:
    from siteline.ingest.mission import IngestOptions, ingest_mission

    opts = IngestOptions(crs=crs, accept_misalignment=accept_misalignment)
    res = _stage(
        "ingest",
        f"mission:{mission_dir}",
        {"site": site, "crs": crs},
        ingest_mission,
        Path(mission_dir),
        site,
        opts,
    )
    return res.to_dict()


@task(retries=2, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def tile_task(scene_id: int) -> dict | None:
    from siteline.tiles import tile_scene

    result, message = _stage("tile", f"scene:{scene_id}", {}, tile_scene, scene_id)
    get_run_logger().info(message)
    return result.summary() if result is not None else None


@task(retries=2, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def process_pair_task(pair_id: int, params: dict | None, site: str) -> dict:
    from siteline import pipeline
    from siteline.pairs import PairParams

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
                "view": v["index"],
                "strategy": v["strategy"],
                "change_ratio": v["change_ratio"],
                "a": join(out.root, "A", v["file"]),
                "mask": join(out.root, "label", v["file"]),
            }
            for v in out.views[:6]
        ],
    }


@task(retries=1, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def build_release_task(site: str, name: str, params: dict | None, publish: bool) -> dict:
    from siteline import pipeline
    from siteline.pairs import PairParams
    from siteline.release import publish_release

    p = PairParams.from_dict(params) if params else PairParams()
    info = _stage("build_release", f"release:{name}", p.to_dict(), pipeline.release, site, name, p)
    if publish:
        info = _stage(
            "publish_release", f"release:{name}:{info.version}", {}, publish_release, name, info.version
        )
    return info.__dict__


def _read(fn, *args):  # noqa: ANN001, ANN202
    """One catalog read function (siteline.catalog) in its own transaction."""
    cat = open_catalog(load_settings())
    try:
        with cat.transaction() as s:
            return fn(s, *args)
    finally:
        cat.dispose()


def _site_of_scene(scene_id: int) -> str:
    return _read(site_name_of_scene, scene_id)


def _site_of_pair(pair_id: int) -> str:
    return _read(site_name_of_pair, pair_id)


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


@flow(name="ingest-mission", flow_run_name=ingest_run_name, task_runner=task_runner(), log_prints=True)
def ingest_mission_flow(
    mission_dir: str, site: str, crs: str | None = None, accept_misalignment: bool = False
) -> int | None:
    """Ingest an uploaded mission, tile its scene, publish dashboards, announce the scene."""
    _tag_run(f"site:{site}")
    with tags(f"site:{site}"):
        # in the flow's own process: the upload folder is on this machine, not on the runner's workers
        res = ingest_task(mission_dir, site, crs, accept_misalignment)
        mission = Path(mission_dir).name
        scan = res.get("scan") or {}
        create_table_artifact(
            [
                {"item": k, "value": str(v)}
                for k, v in {
                    "mission": mission,
                    "manifest_sha256": res["manifest_sha256"],
                    "files": res["files"],
                    "created": res["created"],
                    "message": res["message"],
                }.items()
            ],
            key=artifact_key("mission", site, mission),
            description=f"mission inventory of {mission}",
        )
        if res["scene_id"] is None:
            return None
        tiles = tile_task.submit(res["scene_id"]).result()
        if scan:
            rows = [
                {"statistic": k, "value": str(v)}
                for k, v in {
                    "points": scan.get("point_count"),
                    "density_pts_m2": round(scan.get("density_pts_m2", 0), 2),
                    "classes": scan.get("class_histogram"),
                    "unknown_codes": scan.get("unknown_codes"),
                    "registration": res["registration"].get("source"),
                    "rms_m": res["registration"].get("rms_m"),
                    "alignment_m": (res["registration"].get("alignment") or {}).get("translation_m"),
                    "tiles": (tiles or {}).get("tiles"),
                    "bytes_per_point": (tiles or {}).get("bytes_per_point"),
                }.items()
            ]
            create_table_artifact(
                rows,
                key=artifact_key("scene", site, res["scene_id"]),
                description=f"scene {res['scene_id']} statistics",
            )
        emit_event(
            "siteline.scene.registered",
            resource={"prefect.resource.id": f"siteline.scene.{res['scene_id']}", "siteline.site": site},
            payload={"scene_id": res["scene_id"], "site": site, "pairs": res["pairs"]},
        )
        return res["scene_id"]


@flow(name="tile-scene", flow_run_name="tile-scene-{scene_id}", task_runner=task_runner())
def tile_scene_flow(scene_id: int) -> dict | None:
    _tag_run(f"site:{_site_of_scene(scene_id)}")
    return tile_task.submit(scene_id).result()


@flow(name="process-pair", flow_run_name="process-pair-{pair_id}", task_runner=task_runner())
def process_pair_flow(pair_id: int, params: dict | None = None) -> dict:
    out = process_pair_task.submit(pair_id, params, _site_of_pair(pair_id)).result()
    _pair_dashboards(out)
    return out


def _pair_dashboards(out: dict) -> None:
    site = _site_of_scene(out["t2"])
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
def build_release_flow(site: str, name: str, params: dict | None = None, publish: bool = True) -> dict:
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
    scene_id: int, params: dict | None = None, release_name: str | None = None
) -> list[dict]:
    """Process every pair the scene belongs to (a new scene, or a scene with a new label-set version:
    each scene's newest label set is used); then apply the release policy."""
    site = _site_of_scene(scene_id)
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
