"""The upload watcher reports each completed upload exactly once and never a partial one."""

from __future__ import annotations

import json
from pathlib import Path

from siteline.cli.watch import UPLOADED, upload_event
from siteline.watch import MARKER, UploadWatcher


def test_partial_uploads_wait_until_stable(tmp_path) -> None:
    w = UploadWatcher(tmp_path, stable_s=10)
    up = tmp_path / "mission-a"
    up.mkdir()
    (up / "cloud.las").write_bytes(b"x" * 10)
    assert w.poll(now=0) == []
    (up / "cloud.las").write_bytes(b"x" * 20)  # still growing
    assert w.poll(now=8) == []
    assert w.poll(now=12) == []  # unchanged for only 4 s
    assert w.poll(now=19) == [up]
    assert w.poll(now=100) == []  # reported once


def test_marker_completes_at_once_and_restart_remembers(tmp_path) -> None:
    w = UploadWatcher(tmp_path, stable_s=1000)
    up = tmp_path / "mission-b"
    up.mkdir()
    (up / "photo.JPG").write_bytes(b"jpeg")
    assert w.poll(now=0) == []
    (up / MARKER).touch()
    assert w.poll(now=1) == [up]
    again = UploadWatcher(tmp_path, stable_s=0)
    assert again.poll(now=5) == []
    empty = tmp_path / "empty"
    empty.mkdir()
    assert again.poll(now=10) == []  # an empty folder is not an upload


def test_upload_event_schema(tmp_path) -> None:
    ev = upload_event(tmp_path / "m1", "demo")
    assert ev["event"] == UPLOADED and ev["resource"]["prefect.resource.id"] == "siteline.mission.m1"
    assert ev["payload"] == {"mission_dir": str((tmp_path / "m1").resolve()), "site": "demo"}
    json.dumps(ev)


def test_labels_imported_event_matches_the_deployment_trigger() -> None:
    """The event `siteline labels import` posts is the one the process-scene-pairs deployment's
    trigger expects, and it carries the scene id the trigger passes on."""
    import fnmatch

    import yaml

    from siteline.cli.labels import IMPORTED, imported_event

    doc = yaml.safe_load((Path(__file__).resolve().parents[2] / "deploy" / "prefect.yaml").read_text())
    ev = imported_event(3, 2, "demo")
    json.dumps(ev)
    hits = [
        (d["name"], t)
        for d in doc["deployments"]
        for t in d.get("triggers", [])
        if IMPORTED in t["expect"]
        and fnmatch.fnmatchcase(ev["resource"]["prefect.resource.id"], t["match"]["prefect.resource.id"])
    ]
    assert [name for name, _ in hits] == ["process-scene-pairs"]
    assert hits[0][1]["parameters"] == {"scene_id": "{{ event.payload.scene_id }}"}
    assert ev["payload"]["scene_id"] == 3 and ev["resource"]["siteline.site"] == "demo"
