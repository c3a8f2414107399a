"""The Prefect wiring, exercised once under a session-scoped test harness."""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

import pytest

from siteline.catalog.context import StageContext


@pytest.fixture(scope="module")
def harness(tmp_path_factory):
    os.environ["PREFECT_HOME"] = str(tmp_path_factory.mktemp("prefect-home"))
    os.environ["PREFECT_SERVER_ANALYTICS_ENABLED"] = "false"
    from prefect.testing.utilities import prefect_test_harness

    with prefect_test_harness(server_startup_timeout=90):
        yield


@pytest.fixture(scope="module")
def small_site(tmp_path_factory):
    from siteline.synth import SynthParams, write_site

    out = tmp_path_factory.mktemp("flow-site")
    write_site(out, SynthParams(epochs=2, density_pts_m2=2.0, seed=5))
    return out


def _home(tmp_path, site_dir, monkeypatch):
    from sitehelpers import make_home

    settings = make_home(tmp_path, site_dir=site_dir)
    monkeypatch.setenv("SITELINE_HOME", str(settings.home))
    monkeypatch.setenv("SITELINE_DATABASE_URL", settings.database_url)
    return settings


def _missions(site_dir):
    import json

    return [
        site_dir / e["mission_dir"]
        for e in json.loads((site_dir / "truth" / "site.json").read_text())["epochs"]
    ]


# one candidate view per real camera (no heights, steps or mirrors) at small renders (under the 256 px
# floor, lowered knowingly): the flows need views, not a good sample
SMALL = {
    "pair": {
        "scale": 0.25,
        "point_size_px": 3,
        "views": 3,
        "min_coverage": 0.2,
        "view_params": {"vertical_fractions": [1.0], "forward_fractions": [0.0], "mirror": False},
    },
    "min_image_px": 64,
}


@pytest.mark.e2e
def test_full_chain_to_a_published_release(harness, small_site, tmp_path, monkeypatch) -> None:
    import asyncio

    from prefect.client.orchestration import get_client

    from flows import pipeline

    settings = _home(tmp_path, small_site, monkeypatch)
    monkeypatch.setenv("SITELINE_RELEASE_POLICY", "every-pair")
    monkeypatch.setenv("SITELINE_RELEASE_NAME", "flowrel")
    announced = []
    real_emit = pipeline.emit_event
    monkeypatch.setattr(
        pipeline, "emit_event", lambda *a, **k: announced.append(k["payload"]) or real_emit(*a, **k)
    )
    scenes = [pipeline.ingest_mission_flow(str(m), "demo") for m in _missions(small_site)]
    assert scenes == [1, 2]
    assert announced == [{"scene_id": 2, "site": "demo", "pairs": [1]}]  # the first scene has no pair yet
    outs = pipeline.process_scene_pairs_flow(scenes[1], SMALL)
    assert len(outs) == 1 and outs[0]["views"] > 0
    rel = settings.home / "releases" / "flowrel" / "1.0.0" / "manifest.json"
    assert rel.is_file()

    # exactly once: the same mission dropped again under another folder name announces nothing, and
    # the scene processed again finds the release up to date (no 1.1.0)
    again = tmp_path / "re-drop" / "renamed-mission"
    shutil.copytree(_missions(small_site)[1], again)
    assert pipeline.ingest_mission_flow(str(again), "demo") == 2 and len(announced) == 1
    pipeline.process_scene_pairs_flow(scenes[1], SMALL)
    assert sorted(
        p.name for p in (settings.home / "releases" / "flowrel").iterdir() if not p.name.startswith(".")
    ) == ["1.0.0"]

    async def artifacts():
        async with get_client() as client:
            return {a.key: a for a in await client.read_artifacts() if a.key}

    found = asyncio.run(artifacts())
    keys = set(found)
    assert any(k.startswith("mission-demo-") for k in keys) and any(k.startswith("scene-demo-") for k in keys)
    assert {"pair-demo-1", "samples-demo-pair-1", "release-demo-flowrel", "montage-demo-flowrel"} <= keys
    assert any(k.startswith("progress-pair-1-") for k in keys) and any(
        k.startswith("progress-release-flowrel-") for k in keys
    )
    assert any(k.startswith("note-demo-release-flowrel") for k in keys)  # "up to date", said in the UI
    # the images the UI loads are served by `siteline previews serve` at SITELINE_PREVIEW_URL
    assert found["samples-demo-pair-1"].data.startswith("http://127.0.0.1:4201/previews/pairs/pair-1/")
    release_md = found["release-demo-flowrel"].data
    assert (
        "![montage of flowrel 1.0.0" in release_md
        and "http://127.0.0.1:4201/releases/flowrel/1.0.0/montage.png" in release_md
    )
    assert "why this version | first version" in release_md and "valid fraction | mean" in release_md
    from siteline.catalog import open_catalog
    from siteline.catalog.stages import stage_runs

    cat = open_catalog(settings)
    with cat.transaction() as s:
        runs = stage_runs(s)
    cat.dispose()
    assert {r["stage"] for r in runs} >= {
        "ingest",
        "tile",
        "process_pair",
        "build_release",
        "publish_release",
    }
    assert all(r["status"] == "completed" and r["run_id"] for r in runs)

    # the annotation loop: a corrected label set is imported and announced; the deployment's trigger
    # runs process-scene-pairs for the event's scene, which re-processes the pair on the new version
    # and publishes the next release (a major version: a label set changed)
    from prefect.settings import PREFECT_API_URL

    from siteline.cli.labels import imported_event
    from siteline.cli.watch import post_events
    from siteline.labelsets.export import export_label_set
    from siteline.labelsets.stage import import_labels

    cat = open_catalog(settings)
    export_label_set(cat, 1, tmp_path / "s1.las")
    import laspy
    import numpy as np

    las = laspy.read(tmp_path / "s1.las")
    cls = np.asarray(las.classification).copy()
    cls[(cls != 255) & (cls != 5)] = 5
    las.classification = cls
    las.write(tmp_path / "s1_fixed.las")
    res = import_labels(StageContext(cat, settings), 1, tmp_path / "s1_fixed.las")
    cat.dispose()
    event = imported_event(1, res.version, "demo")
    post_events(PREFECT_API_URL.value(), [event])
    outs = pipeline.process_scene_pairs_flow(event["payload"]["scene_id"], SMALL)
    assert len(outs) == 1
    rel2 = settings.home / "releases" / "flowrel" / "2.0.0" / "manifest.json"
    lineage = json.loads(rel2.read_text())["lineage"]
    assert {sc["id"]: sc["label_set_version"] for sc in lineage["scenes"]} == {1: res.version, 2: 1}


def test_retry_then_success_and_permanent_failure_recorded(
    harness, small_site, tmp_path, monkeypatch
) -> None:
    import siteline.pipeline as tiles_pkg  # the pipeline calls the tile stage
    from flows import pipeline
    from siteline.catalog import open_catalog
    from siteline.catalog.models import Scene
    from siteline.catalog.stages import stage_runs
    from siteline.ingest.stage import ingest_mission

    settings = _home(tmp_path, small_site, monkeypatch)
    cat = open_catalog(settings)
    sid = ingest_mission(StageContext(cat, settings), _missions(small_site)[0], "demo").scene_id
    real = tiles_pkg.tile_scene
    calls = {"n": 0}

    def flaky(*a, **k):
        calls["n"] += 1
        if calls["n"] == 1:
            raise OSError("disk hiccup")
        return real(*a, **k)

    monkeypatch.setattr(tiles_pkg, "tile_scene", flaky)
    assert pipeline.tile_scene_flow(sid).points > 0
    assert calls["n"] == 2

    sid2 = ingest_mission(StageContext(cat, settings), _missions(small_site)[1], "demo").scene_id

    def broken(*a, **k):
        raise OSError("store unreachable")

    monkeypatch.setattr(tiles_pkg, "tile_scene", broken)
    state = pipeline.tile_scene_flow(sid2, return_state=True)
    assert state.is_failed()
    with cat.transaction() as s:
        failed = [r for r in stage_runs(s, subject=f"scene:{sid2}") if r["status"] == "failed"]
    assert failed and "store unreachable" in failed[-1]["error"] and failed[-1]["run_id"]
    with cat.transaction() as s:
        assert s.get(Scene, sid2).status == "registered" and s.get(Scene, sid2).tile_store_uri is None
    assert not (Path(settings.store.url) / "tiles" / f"scene-{sid2}.zarr").exists()
    monkeypatch.setattr(tiles_pkg, "tile_scene", real)
    assert pipeline.tile_scene_flow(sid2).points > 0
    cat.dispose()


def test_upload_event_reaches_the_api(harness, tmp_path) -> None:
    from prefect.settings import PREFECT_API_URL

    from siteline.cli.watch import post_events, upload_event

    sent = upload_event(tmp_path / "m9", "demo")
    post_events(PREFECT_API_URL.value(), [sent])
    # the server stored it: read back by its name, with its resource and payload
    from datetime import UTC, datetime, timedelta

    from prefect.client.orchestration import get_client
    from prefect.events.filters import EventFilter, EventNameFilter, EventOccurredFilter

    since = datetime.now(UTC) - timedelta(minutes=5)
    with get_client(sync_client=True) as client:
        for _ in range(50):  # events are written by the server's consumer a moment after they arrive
            page = client.read_events(EventFilter(
                occurred=EventOccurredFilter(since=since, until=datetime.now(UTC) + timedelta(minutes=1)),
                event=EventNameFilter(name=[sent["event"]])), limit=50)  # fmt: skip
            got = [e for e in page.events if str(e.id) == sent["id"]]
            if got:
                break
            time.sleep(0.2)
    assert got, "the upload event never reached the server's event store"
    assert got[0].resource.id == "siteline.mission.m9" and got[0].payload["site"] == "demo"


@pytest.mark.e2e
@pytest.mark.slow  # ~55 s (a Dask cluster, S3 and PostgreSQL): `make test-all` runs it
def test_dask_workers_sharing_only_catalog_and_object_store_match_threads(
    harness, small_site, tmp_path, monkeypatch, postgres_url, s3_store
) -> None:
    """Threads on one machine (SQLite, local store) against Dask workers that, like workers on other
    machines, share nothing with the flow but the PostgreSQL catalog and an S3 store: each worker has
    its own SITELINE_HOME. Tiles, labels and renders must come out identical."""
    from prefect_dask import DaskTaskRunner

    from flows import pipeline
    from siteline.catalog import open_catalog
    from siteline.ingest.stage import ingest_mission
    from siteline.stores import open_store
    from siteline.stores.layout import pair_label_stores

    results = {}
    for kind in ("threads", "dask"):
        if kind == "threads":
            settings = _home(tmp_path / kind, small_site, monkeypatch)
        else:
            from sitehelpers import make_home

            settings = make_home(tmp_path / kind, postgres_url, small_site, store_url=s3_store)
            monkeypatch.setenv("SITELINE_HOME", str(settings.home))
            monkeypatch.setenv("SITELINE_DATABASE_URL", settings.database_url)
            monkeypatch.setenv("SITELINE_STORE_URL", s3_store)
        cat = open_catalog(settings)
        for m in _missions(small_site):
            ingest_mission(StageContext(cat, settings), m, "demo")
        cat.dispose()
        if kind == "dask":
            worker_home = tmp_path / "worker-home"
            runner = DaskTaskRunner(
                cluster_kwargs={
                    "n_workers": 2,
                    "threads_per_worker": 1,
                    "host": "127.0.0.1",
                    "dashboard_address": None,
                    "env": {"SITELINE_HOME": str(worker_home)},
                }
            )
            flows = (
                pipeline.tile_scene_flow.with_options(task_runner=runner),
                pipeline.process_pair_flow.with_options(task_runner=runner),
            )
        else:
            flows = (pipeline.tile_scene_flow, pipeline.process_pair_flow)
        tilings = [flows[0](sid) for sid in (1, 2)]
        tiles = [t.checksum for t in tilings if t is not None]
        assert len(tiles) == 2
        pair = flows[1](1, SMALL)
        renders = [open_store(m).read_bytes(m) for m in pair["masks"]]
        results[kind] = (tiles, pair["labels"], pair["radius_m"], renders)
        if kind == "dask":
            assert pair["root"].startswith(s3_store + "/pairs/")
            s3 = open_store(s3_store)
            assert s3.is_complete(f"{s3_store}/tiles/scene-1.zarr")
            um = int(round(pair["radius_m"] * 1e6))
            [labels] = pair_label_stores(s3, 1)
            assert labels.startswith(f"{s3_store}/labels/pair-1-r{um}um") and s3.is_complete(labels)
            # nothing landed in either machine's local store; the workers fetched the LAS into their cache
            assert not (settings.home / "stores").exists() and not (worker_home / "stores").exists()
            assert list((worker_home / "staging" / "cache").rglob("*"))
    assert results["threads"] == results["dask"]


def test_progress_words_name_their_unit() -> None:
    """The UI's progress says what it counts: 'hashing 0.0 MB of 8.9 MB', not 'hashing 0 of 8,869,660'."""
    from flows.ui import counted

    assert counted("hashing", 0, 8_869_660) == "0.0 MB of 8.9 MB"
    assert counted("reading points", 5_000, 110_000) == "5,000 of 110,000 points"
    assert counted("renders", 3, None) == "3 views"


def test_an_expected_failure_is_logged_without_a_traceback(
    harness, small_site, tmp_path, monkeypatch
) -> None:
    """A SitelineError (here a tile store the scene's LAS is missing from) or a full disk fails the
    run with its message in the run logs and no traceback; a programming error keeps its traceback."""
    import errno
    import logging

    import siteline.pipeline as tiles_pkg
    from flows import pipeline
    from siteline.catalog import open_catalog
    from siteline.errors import TileError
    from siteline.ingest.stage import ingest_mission

    settings = _home(tmp_path, small_site, monkeypatch)
    cat = open_catalog(settings)
    sid = ingest_mission(StageContext(cat, settings), _missions(small_site)[0], "demo").scene_id
    cat.dispose()
    records: list[logging.LogRecord] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            records.append(record)

    handler = Keep()
    logging.getLogger("prefect").addHandler(handler)
    try:
        full = OSError(errno.ENOSPC, "No space left on device")
        for exc in (
            TileError("scene 1: point cloud cloud.las is missing from the store."),
            full,
            KeyError("bug"),
        ):
            records.clear()

            def fail(*a, exc=exc, **k):
                raise exc

            monkeypatch.setattr(tiles_pkg, "tile_scene", fail)
            assert pipeline.tile_scene_flow(sid, return_state=True).is_failed()
            failed = [r for r in records if r.levelno >= logging.ERROR]
            assert failed and any(str(exc) in r.getMessage() for r in failed)
            if exc is full:  # not retried, and told what to free
                assert any("the disk is full" in r.getMessage() for r in failed)
                assert not any("Retries are exhausted" in r.getMessage() for r in failed)
            traced = [r for r in failed if r.exc_info or r.exc_text]
            assert bool(traced) == isinstance(exc, KeyError), [r.getMessage() for r in traced]
    finally:
        logging.getLogger("prefect").removeHandler(handler)


def test_a_crashed_run_says_why_on_its_own_page(harness) -> None:
    """deploy/reporter.py: a siteline run marked Crashed (as the heartbeat automation marks it) and
    rescheduled gets a markdown artifact that says why, and its progress bar says where it stopped;
    a second look repeats nothing."""
    import time as _time
    from datetime import UTC, datetime, timedelta

    from prefect import flow
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.actions import ArtifactCreate
    from prefect.client.schemas.filters import ArtifactFilter, ArtifactFilterFlowRunId
    from prefect.states import Crashed, Running, Scheduled

    from deploy import reporter

    @flow(name="siteline-probe")
    def probe() -> None:  # never run: its run is driven by hand
        return None

    with get_client(sync_client=True) as client:
        run = client.create_flow_run(probe, tags=["siteline"], name="scene-9-labels-v2")
        other = client.create_flow_run(probe, tags=["elsewhere"], name="not-ours")
        bar = client.create_artifact(ArtifactCreate(key=f"progress-x-{str(run.id)[:8]}", type="progress", data=42.0,
                                                    flow_run_id=run.id, description="pair 1: renders 3 of 6"))  # fmt: skip
        why = "no heartbeat for 40 s: its process or machine died"
        for rid in (run.id, other.id):
            client.set_flow_run_state(rid, Running(), force=True)
            client.set_flow_run_state(rid, Crashed(message=why), force=True)
            client.set_flow_run_state(rid, Scheduled(name="AwaitingRetry", message="rescheduled"), force=True)
        since = datetime.now(UTC) - timedelta(minutes=5)
        done: set[str] = set()
        reported: list[str] = []
        mine = ArtifactFilter(flow_run_id=ArtifactFilterFlowRunId(any_=[run.id]))

        def why_text() -> str:  # the newest why artifact of the run ("" before the first)
            whys = [a for a in client.read_artifacts(artifact_filter=mine) if a.key == f"why-{run.id}"]
            return max(whys, key=lambda a: a.created).data if whys else ""

        # events reach the events API a little apart: the reporter writes again when the reschedule arrives
        t0 = _time.monotonic()
        while _time.monotonic() - t0 < 60 and "rescheduled (attempt" not in why_text():
            reported += reporter.report(client, since, done)
            _time.sleep(1)
        assert reported and all(r == "scene-9-labels-v2" for r in reported), reported
        arts = client.read_artifacts(artifact_filter=mine)
        text = why_text()
        assert "Why scene-9-labels-v2 stopped" in text and why in text and "rescheduled (attempt" in text
        assert "42 % done (pair 1: renders 3 of 6)" in text
        progress = next(a for a in arts if a.id == bar.id)
        assert progress.description.startswith("stopped at 42 %: rescheduled after a crash: "), (
            progress.description
        )
        # nothing new: nothing written again, also by a reporter that starts afresh
        assert reporter.report(client, since, done) == [] and reporter.report(client, since, set()) == []
        assert not [
            a
            for a in client.read_artifacts(
                artifact_filter=ArtifactFilter(flow_run_id=ArtifactFilterFlowRunId(any_=[other.id]))
            )
            if a.key and a.key.startswith("why-")
        ]
