"""Two missions with the same content ingested at once, one failing (SQLite and PostgreSQL): the failed ingest removes the
blobs it added, never a blob the other one recorded. The interleaving that lost a blob is forced
with events: A stores the blobs, B finds them stored (copies nothing), A fails and removes them,
then B records its mission."""

from __future__ import annotations

import hashlib
import threading
from pathlib import Path

import pytest
import sqlalchemy as sa
from sitehelpers import SYNTH, copy_mission, make_home

import siteline.ingest.stage as stage
from siteline.catalog import open_catalog
from siteline.catalog.context import StageContext
from siteline.catalog.models import MissionFile, Scene
from siteline.catalog.sites import add_site
from siteline.ingest.stage import ingest_mission
from siteline.site.fence import load_fence_geojson
from siteline.site.spec import make_site_spec
from siteline.stores import layout

WAIT_S = 60.0


class _Crash(RuntimeError):
    pass


def _wait(event: threading.Event, what: str) -> None:
    if not event.wait(WAIT_S):
        raise TimeoutError(f"the test's interleaving stalled waiting for {what}")


@pytest.mark.parametrize("b_records_first", [False, True])
def test_a_failed_ingest_never_removes_a_blob_another_mission_records(
    db_url, synth_site, tmp_path, monkeypatch, b_records_first
) -> None:
    site_settings = make_home(tmp_path, url=db_url, site_dir=synth_site)
    cat = open_catalog(site_settings)
    try:
        _race(cat, site_settings, synth_site, tmp_path, monkeypatch, b_records_first)
    finally:
        cat.dispose()


def _race(cat, site_settings, synth_site, tmp_path, monkeypatch, b_records_first) -> None:
    ring = load_fence_geojson(synth_site / "fence.geojson", SYNTH.origin)
    with cat.transaction() as s:
        add_site(s, make_site_spec("other", SYNTH.crs, SYNTH.origin, [*ring, ring[0]]))
    # the same files, every blob shared; B holds one more (a mission of the same content is one
    # mission: its ingests take turns, siteline.ingest.stage)
    a = copy_mission(synth_site, 0, tmp_path / "a")
    b = copy_mission(synth_site, 0, tmp_path / "b")
    (b / "notes.txt").write_text("flown again for the second site\n")
    a_stored, b_stored, b_recorded, a_cleaned = (threading.Event() for _ in range(4))
    store, record, remove = stage.store_mission, stage.record_ingest, stage.remove_blobs

    def store_mission(checked, *args, **kwargs):
        if Path(checked.manifest.root) == b:
            _wait(a_stored, "A to store its blobs")
        store(checked, *args, **kwargs)
        if Path(checked.manifest.root) == a:  # A fails once B found its blobs stored (or recorded them)
            a_stored.set()
            _wait(b_recorded if b_records_first else b_stored, "B")
            raise _Crash("A fails after storing its blobs")
        b_stored.set()
        if not b_records_first:
            _wait(a_cleaned, "A to remove its blobs")

    def record_ingest(session, site_id, checked, run):
        ids = record(session, site_id, checked, run)
        session.commit()
        b_recorded.set()
        return ids

    def remove_blobs(store_, shas):
        remove(store_, shas)
        a_cleaned.set()

    monkeypatch.setattr(stage, "store_mission", store_mission)
    monkeypatch.setattr(stage, "record_ingest", record_ingest)
    monkeypatch.setattr(stage, "remove_blobs", remove_blobs)
    outcome: dict[str, object] = {}

    def run(name: str, mission: Path, site: str) -> None:
        try:
            outcome[name] = ingest_mission(StageContext(cat, site_settings), mission, site, workers=1)
        except BaseException as exc:  # noqa: BLE001 - handed to the test thread
            outcome[name] = exc

    threads = [
        threading.Thread(target=run, args=("a", a, "demo")),
        threading.Thread(target=run, args=("b", b, "other")),
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join(WAIT_S * 3)
    assert isinstance(outcome["a"], _Crash), outcome["a"]
    assert not isinstance(outcome["b"], BaseException), outcome["b"]
    assert a_cleaned.is_set()
    with cat.transaction() as s:
        files = s.execute(sa.select(MissionFile.sha256)).scalars().all()
        samples = [sc.statistics["stable_sample_sha256"] for sc in s.execute(sa.select(Scene)).scalars()]
    assert files and len(samples) == 1
    store_ = site_settings.store
    for sha in {*files, *samples}:  # every blob B recorded is stored, whole
        uri = layout.blob(store_, sha)
        assert store_.exists(uri), sha
        assert hashlib.sha256(store_.read_bytes(uri)).hexdigest() == sha
