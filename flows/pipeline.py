"""Prefect flows of siteline: thin orchestration over ``siteline.pipeline``, passing ids and paths only.

Chain: an upload event (``siteline.mission.uploaded``, from ``siteline watch`` or POST /api/events)
triggers ``ingest-mission``; it registers and tiles the scene and, when the mission brought work (a new
scene with pairs, or pairs nobody processed), emits ``siteline.scene.registered``, which triggers
``process-scene-pairs``; with ``SITELINE_RELEASE_POLICY=every-pair`` that flow then builds and
publishes a release with the site's release settings (``on-demand``: run ``build-release`` yourself).
A release whose inputs equal the latest version's is not published again. ``siteline labels import``
posts ``siteline.labels.imported`` once a corrected label set is recorded; it triggers
``process-scene-pairs`` for that scene too.

Concurrency: pair processing holds a slot of the global concurrency limit ``siteline-pairs``, release
building one of ``siteline-release`` (`make serve` creates both); the catalog's locks keep one writer
per pair output and release name whatever runs them. Crashes: ``deploy/service.py`` makes the
automations that mark runs whose heartbeats stopped as crashed and reschedule crashed runs; a
rescheduled run reuses every finished output, and marks the task runs its killed attempt left running.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from prefect import flow, get_run_logger, tags, task
from prefect.cache_policies import NO_CACHE
from prefect.concurrency.sync import concurrency
from prefect.events import emit_event
from prefect.runtime import flow_run

from flows.runner import cluster_executor, task_runner
from flows.ui import RunProgress, ingest_dashboards, note, pair_dashboards, release_dashboards, slug, tag_run
from siteline import pipeline
from siteline.catalog import Catalog, open_catalog
from siteline.catalog.context import StageContext
from siteline.catalog.pairs import pair_ids_of_scene, site_name_of_pair
from siteline.catalog.scenes import site_name_of_scene
from siteline.catalog.stages import record_failure
from siteline.config import Settings, load_settings
from siteline.errors import SitelineError, StoreError
from siteline.ingest.options import IngestOptions
from siteline.pointpass import TilingResources
from siteline.progress import Progress
from siteline.records.pairs import PairOutput
from siteline.records.params.pairs import PairParams
from siteline.records.params.release import ReleaseKnobs
from siteline.records.release import ReleaseInfo, ReleaseOptions
from siteline.records.runs import StageRun
from siteline.records.tiling import SceneTiling
from siteline.stores import join
from siteline.stores.diskspace import disk_full, full_disk_message

# the library's INFO lines (views, renders, releases) reach the run logs: PREFECT_LOGGING_EXTRA_LOGGERS=siteline
# gives the logger Prefect's handlers, this its level
logging.getLogger("siteline").setLevel(logging.INFO)


class MessageOnly(logging.Filter):
    """Prefect logs a failed task or flow run with its traceback; a SitelineError is an expected
    failure whose message says what to fix (a truncated LAS, an unknown site), so its records keep the
    message and drop the traceback, and so does a full disk (its message says what to free). Any
    other exception keeps its traceback."""

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        if isinstance(exc, SitelineError):
            record.exc_info, record.exc_text = None, None
        elif exc is not None and disk_full(exc):
            record.msg, record.args = (
                f"{record.getMessage()}: {full_disk_message(exc, load_settings().home)}",
                None,
            )
            record.exc_info, record.exc_text = None, None
        return True


for _name in ("prefect.task_runs", "prefect.flow_runs"):
    logging.getLogger(_name).addFilter(MessageOnly())
T = TypeVar("T")
PAIR_SLOTS = "siteline-pairs"
RELEASE_SLOTS = "siteline-release"
# a live holder renews its slot's lease every fraction of this (Prefect's renewal thread); a killed
# holder's slot is freed when the lease runs out (the server's repossessor looks every 15 s), so a
# machine failure blocks no other run for long. 60 s is the shortest lease the server accepts.
SLOT_LEASE_S = 60


def transient(task: Any, task_run: Any, state: Any) -> bool:
    """Retry I/O only: store errors, OS and network errors, a lost database connection. Never bad
    input (a SitelineError says what to fix), a full disk, or a programming error (it would fail again)."""
    import sqlalchemy as sa

    try:
        state.result()
    except StoreError as exc:
        return not disk_full(exc)  # a full disk stays full: its one-line message says what to free
    except SitelineError:
        return False
    except (OSError, TimeoutError, ConnectionError) as exc:
        return not disk_full(exc)
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
    stage: str, subject: str, params: dict[str, Any], progress: Progress, fn: Callable[..., T], *args: Any,
    **kwargs: Any,
) -> T:  # fmt: skip
    """Run a pipeline step under this flow run, reporting to ``progress``; on failure record it in the
    catalog (its own transaction) and re-raise."""
    with _catalog() as (cat, settings):
        try:
            return fn(StageContext(cat, settings, progress, _run_id()), *args, **kwargs)
        except Exception as exc:
            with cat.transaction() as s:
                record_failure(s, StageRun(stage, subject, params, run_id=_run_id()), exc)
            raise


def _read(fn: Callable[..., T], *args: Any) -> T:
    """One catalog read function (siteline.catalog) in its own transaction."""
    with _catalog() as (cat, _), cat.transaction() as s:
        return fn(s, *args)


def _call(fn: Callable[..., T], *args: Any) -> T:
    """A pipeline function that takes (catalog, ...) and reads only."""
    with _catalog() as (cat, _):
        return fn(cat, *args)


def _knobs(release_settings: dict[str, Any] | None) -> ReleaseKnobs | None:
    """The flow parameter ``release_settings`` (siteline.release.knobs JSON: a preset, pair knobs,
    pad, min_image_px) as a layer over the site's settings."""
    return (
        ReleaseKnobs.from_dict(release_settings, "flow parameter release_settings")
        if release_settings
        else None
    )


def _close_stale_runs() -> None:
    """On a rescheduled run (run count > 1): the task runs and sub-flow runs its killed attempt left
    Running or Pending are marked Crashed, so the UI shows only this attempt's work as running."""
    if not flow_run.id or (flow_run.run_count or 1) <= 1:
        return
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import (
        FlowRunFilter,
        FlowRunFilterId,
        FlowRunFilterParentFlowRunId,
        FlowRunFilterState,
        FlowRunFilterStateType,
        TaskRunFilter,
        TaskRunFilterState,
        TaskRunFilterStateType,
    )
    from prefect.client.schemas.objects import StateType
    from prefect.states import Crashed

    live = [StateType.RUNNING, StateType.PENDING]
    message = f"left by attempt {flow_run.run_count - 1} of flow run {flow_run.name}, which was killed"
    with get_client(sync_client=True) as client:
        stale_tasks = client.read_task_runs(
            flow_run_filter=FlowRunFilter(id=FlowRunFilterId(any_=[flow_run.id])),
            task_run_filter=TaskRunFilter(state=TaskRunFilterState(type=TaskRunFilterStateType(any_=live))),
        )
        for tr in stale_tasks:
            client.set_task_run_state(tr.id, Crashed(message=message), force=True)
        try:
            _abandon_progress(client, [tr.id for tr in stale_tasks], message)
        except Exception as exc:  # a bar left standing must not stop the recovery
            get_run_logger().warning("could not mark the killed attempt's progress abandoned: %s", exc)
        children = client.read_flow_runs(
            flow_run_filter=FlowRunFilter(
                parent_flow_run_id=FlowRunFilterParentFlowRunId(any_=[flow_run.id]),
                state=FlowRunFilterState(type=FlowRunFilterStateType(any_=live)),
            )
        )
        for fr in children:
            client.set_flow_run_state(fr.id, Crashed(message=message), force=True)
    if stale_tasks or children:
        get_run_logger().info(
            "attempt %d: marked %d task runs and %d sub-flow runs of the killed attempt crashed; finished "
            "outputs are reused", flow_run.run_count, len(stale_tasks), len(children),
        )  # fmt: skip


@contextmanager
def _slot(limit: str, what: str) -> Iterator[None]:
    """Hold one slot of the global concurrency limit ``limit`` for ``what``, saying in the run log
    that it waits and for how long it waited (a run waiting on a full limit shows Running)."""
    log = get_run_logger()
    log.info("%s waits for a %s slot (the service's limit on such work at once)", what, limit)
    t0 = time.monotonic()
    with concurrency(limit, occupy=1, lease_duration=SLOT_LEASE_S, raise_on_lease_renewal_failure=False):
        waited = time.monotonic() - t0
        log.info("%s got a %s slot after %.0f s", what, limit, waited)
        yield


def _abandon_progress(client: Any, task_run_ids: list[Any], message: str) -> None:
    """Say on the progress artifacts of the killed attempt's task runs that their work was abandoned
    (their bars would otherwise stand still at their last figure)."""
    if not task_run_ids:
        return
    from prefect.client.schemas.actions import ArtifactUpdate
    from prefect.client.schemas.filters import ArtifactFilter, ArtifactFilterTaskRunId, ArtifactFilterType

    arts = client.read_artifacts(
        artifact_filter=ArtifactFilter(
            task_run_id=ArtifactFilterTaskRunId(any_=task_run_ids), type=ArtifactFilterType(any_=["progress"])
        )
    )
    for art in arts:
        client.update_artifact(
            art.id,
            ArtifactUpdate(data=art.data, description=f"{art.description or ''} - abandoned: {message}"),
        )


# --- tasks -------------------------------------------------------------------------------------


@task(retries=2, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def ingest_task(mission_dir: str, site: str, opts: IngestOptions) -> pipeline.Ingested:
    progress = RunProgress(slug("ingest", site, Path(mission_dir).name), f"ingest of {Path(mission_dir).name}",
                           {"hashing": 1.0, "reading points": 1.0, "storing": 1.0, "partitioning": 2.0, "writing tiles": 2.0})  # fmt: skip
    done = _stage(
        "ingest", f"mission:{mission_dir}", {"site": site, "crs": opts.crs}, progress, pipeline.ingest,
        Path(mission_dir), site, opts,
    )  # fmt: skip
    progress.finish(done.ingest.message)
    return done


@task(retries=2, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def tile_task(scene_id: int) -> SceneTiling | None:
    progress = RunProgress(
        slug("tile", scene_id), f"tiling of scene {scene_id}", {"partitioning": 1.0, "writing tiles": 2.0}
    )
    with cluster_executor() as executor:  # on a Dask runner, the cluster's workers write the tiles
        done = _stage("tile", f"scene:{scene_id}", {}, progress, pipeline.tile_scenes, [scene_id],
                      resources=TilingResources(executor=executor))  # fmt: skip
    for outcome in done:
        get_run_logger().info(outcome.message)
    progress.finish(done[0].message if done else f"scene {scene_id} was tiled already")
    return done[0].tiling if done else None


@task(retries=2, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def process_pair_task(pair_id: int, pair_params: dict[str, Any]) -> PairOutput:
    p = PairParams.from_dict(pair_params)
    with _slot(PAIR_SLOTS, f"pair {pair_id}"):
        progress = RunProgress(
            slug("pair", pair_id), f"pair {pair_id}", {"labels": 1.0, "views": 1.0, "renders": 4.0}
        )
        outs = _stage(
            "process_pair",
            f"pair:{pair_id}",
            p.to_dict(),
            progress,
            pipeline.process_pairs,
            [pair_id],
            p,
        )
    out = outs[pair_id]
    progress.finish(f"{len(out.views)} views at {out.root}")
    return out


@task(retries=1, retry_delay_seconds=1, retry_condition_fn=transient, cache_policy=NO_CACHE)
def build_release_task(
    site: str, name: str, release_settings: dict[str, Any] | None, publish: bool
) -> ReleaseInfo:
    with _slot(RELEASE_SLOTS, f"release {name}"):
        progress = RunProgress(slug("release", name), f"release {name}",
                               {"labels": 1.0, "views": 1.0, "renders": 4.0, "release images": 2.0})  # fmt: skip
        info = _stage(
            "build_release", f"release:{name}", release_settings or {}, progress, pipeline.release, site, name,
            _knobs(release_settings), ReleaseOptions(publish=publish),
        )  # fmt: skip
    progress.finish(f"{info.version} up to date" if info.up_to_date else f"{info.version} {info.status}")
    return info


# --- flows -------------------------------------------------------------------------------------


def _ingest_name() -> str:
    p = flow_run.parameters
    return slug("ingest", p["site"], Path(p["mission_dir"]).name)


@flow(name="ingest-mission", flow_run_name=_ingest_name, task_runner=task_runner(), log_prints=True)
def ingest_mission_flow(
    mission_dir: str, site: str, crs: str | None = None, accept_misalignment: bool = False,
    captured_at: str | None = None, reason: str = "manual run",
) -> int | None:  # fmt: skip
    """Ingest an uploaded mission and tile its scene; announce the scene when it brought work."""
    from datetime import datetime

    _close_stale_runs()
    mission = Path(mission_dir).name
    tag_run(f"site:{site}", f"mission:{mission}")
    get_run_logger().info("ingest of %s into site %s (%s)", mission, site, reason)
    opts = IngestOptions(crs=crs, accept_misalignment=accept_misalignment,
                         captured_at=datetime.fromisoformat(captured_at) if captured_at else None)  # fmt: skip
    with tags(f"site:{site}"):
        # in the flow's own process: the upload folder is on this machine, not on the runner's workers
        done = ingest_task.with_options(task_run_name=slug("ingest", mission))(mission_dir, site, opts)
    ingest_dashboards(site, mission, done)
    sid = done.ingest.scene_id
    if sid is None:
        return None
    tag_run(f"scene:{sid}")
    pairs = done.ingest.pairs if done.ingest.created else _call(pipeline.pending_pairs, sid)
    if not pairs:
        why = (f"scene {sid} is the site's first scene (or its neighbours are not ingested): it has no pair yet"
               if done.ingest.created else f"mission {mission} is already scene {sid}, and its pairs are processed")  # fmt: skip
        note(site, f"scene {sid}", f"{why}: nothing to announce, no pair is processed.")
        return sid
    emit_event(
        "siteline.scene.registered",
        resource={"prefect.resource.id": f"siteline.scene.{sid}", "siteline.site.spec": site},
        payload={"scene_id": sid, "site": site, "pairs": pairs},
    )
    get_run_logger().info("scene %d announced: pairs %s to process", sid, pairs)
    return sid


def _scene_name() -> str:
    p = flow_run.parameters
    return slug("scene", p["scene_id"], p.get("reason") or "manual")


@flow(name="process-scene-pairs", flow_run_name=_scene_name, task_runner=task_runner())
def process_scene_pairs_flow(
    scene_id: int, release_settings: dict[str, Any] | None = None, release_name: str | None = None,
    reason: str = "manual run",
) -> list[dict[str, Any]]:  # fmt: skip
    """Process every pair the scene belongs to (a new scene, or a scene with a new label-set version:
    each scene's newest label set is used) with the site's release settings, then apply the release
    policy."""
    _close_stale_runs()
    site = _read(site_name_of_scene, scene_id)
    tag_run(f"site:{site}", f"scene:{scene_id}")
    pair_ids = _read(pair_ids_of_scene, scene_id)
    if not pair_ids:
        note(
            site,
            f"scene {scene_id}",
            f"scene {scene_id} has no pair yet (ingest its neighbours): nothing to process.",
        )
        return []
    params = _call(pipeline.release_parameters, site, _knobs(release_settings))
    get_run_logger().info(
        "scene %d (%s): pairs %s at scale %g, %d px points, %d views", scene_id, reason, pair_ids,
        params.pair.scale, params.pair.point_size_px, params.pair.views,
    )  # fmt: skip
    with tags(f"site:{site}", f"scene:{scene_id}"):
        futures = [
            process_pair_task.with_options(task_run_name=f"pair-{pid}", tags=[f"pair:{pid}"]).submit(
                pid, params.pair.to_dict()
            )
            for pid in pair_ids
        ]
        outs = [f.result() for f in futures]
    settings = load_settings()
    for out in outs:
        pair_dashboards(settings, site, out)
    if settings.release_policy == "every-pair":
        name = release_name or settings.release_name or f"{site}-cd"
        build_release_flow(site, name, release_settings, True, reason=f"scene {scene_id}: {reason}")
    return [_summary(o) for o in outs]


def _release_name() -> str:
    p = flow_run.parameters
    return slug("release", p["name"], p.get("reason") or "manual")


@flow(name="build-release", flow_run_name=_release_name, task_runner=task_runner())
def build_release_flow(
    site: str, name: str, release_settings: dict[str, Any] | None = None, publish: bool = True,
    reason: str = "manual run",
) -> dict[str, Any]:  # fmt: skip
    """Build (and publish) release ``name`` of ``site`` with its release settings; nothing when the
    latest version already has these inputs."""
    _close_stale_runs()
    tag_run(f"site:{site}", f"release:{name}")
    info = build_release_task.with_options(task_run_name=slug("release", name))(
        site, name, release_settings, publish
    )
    tag_run(f"release:{name}:{info.version}")
    if info.up_to_date:  # its artifacts are there already
        note(site, f"release {name}", f"release {name} is up to date: {info.version} ({info.status}) has these "
             "pairs, outputs, label sets and parameters, so nothing was built or published.")  # fmt: skip
    else:
        get_run_logger().info(
            "release %s %s %s (%s) at %s", name, info.version, info.status, info.reason, info.root
        )
        release_dashboards(load_settings(), site, info)
    return info.to_dict()


@flow(name="tile-scene", flow_run_name="tile-scene-{scene_id}", task_runner=task_runner())
def tile_scene_flow(scene_id: int) -> SceneTiling | None:
    """Tile a scene that is not tiled yet (ingest tiles new scenes itself)."""
    _close_stale_runs()
    tag_run(f"site:{_read(site_name_of_scene, scene_id)}", f"scene:{scene_id}")
    return tile_task.with_options(task_run_name=f"tile-scene-{scene_id}").submit(scene_id).result()


@flow(name="process-pair", flow_run_name="process-pair-{pair_id}", task_runner=task_runner())
def process_pair_flow(pair_id: int, release_settings: dict[str, Any] | None = None) -> dict[str, Any]:
    """Process one pair with its site's release settings (and ``release_settings`` over them)."""
    _close_stale_runs()
    site = _read(site_name_of_pair, pair_id)
    tag_run(f"site:{site}", f"pair:{pair_id}")
    params = _call(pipeline.release_parameters, site, _knobs(release_settings))
    out = (
        process_pair_task.with_options(task_run_name=f"pair-{pair_id}")
        .submit(pair_id, params.pair.to_dict())
        .result()
    )
    pair_dashboards(load_settings(), site, out)
    return _summary(out)


def _summary(out: PairOutput) -> dict[str, Any]:
    """A pair's outputs as a flow returns them: ids, views, radius, 3D label counts, where they are."""
    return {
        "pair": out.pair_id, "t1": out.t1, "t2": out.t2, "views": len(out.views), "root": out.root,
        "radius_m": out.radius_m, "labels": {k: dict(v) for k, v in out.labels.counts.items()},
        "masks": [join(out.root, "label", v.file) for v in out.views],
    }  # fmt: skip
