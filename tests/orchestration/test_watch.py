"""The upload watcher reports each completed upload exactly once and never a partial one."""

from __future__ import annotations

import json
from pathlib import Path

from siteline.cli.watch import UPLOADED, upload_event
from siteline.ingest.watch import MARKER, UploadWatcher


def _announce(w: UploadWatcher, now: float) -> list[Path]:
    """One poll with every upload found confirmed, as `siteline watch` does once its event is out."""
    done = w.poll(now=now)
    for folder in done:
        w.confirm(folder)
    return done


def test_partial_uploads_wait_until_stable(tmp_path) -> None:
    w = UploadWatcher(tmp_path, stable_s=10)
    up = tmp_path / "mission-a"
    up.mkdir()
    (up / "cloud.las").write_bytes(b"x" * 10)
    assert _announce(w, 0) == []
    (up / "cloud.las").write_bytes(b"x" * 20)  # still growing
    assert _announce(w, 8) == []
    assert _announce(w, 12) == []  # unchanged for only 4 s
    assert _announce(w, 19) == [up]
    assert _announce(w, 100) == []  # reported once


def test_marker_completes_at_once_and_restart_remembers(tmp_path) -> None:
    w = UploadWatcher(tmp_path, stable_s=1000)
    up = tmp_path / "mission-b"
    up.mkdir()
    (up / "photo.JPG").write_bytes(b"jpeg")
    assert _announce(w, 0) == []
    (up / MARKER).touch()
    assert _announce(w, 1) == [up]
    again = UploadWatcher(tmp_path, stable_s=0)
    assert _announce(again, 5) == []
    empty = tmp_path / "empty"
    empty.mkdir()
    assert _announce(again, 10) == []  # an empty folder is not an upload


def test_an_upload_fixed_in_place_is_announced_again(tmp_path) -> None:
    """A failed upload fixed in place (its LAS replaced, the marker touched) is announced again, by
    this watcher and by a restarted one; an upload whose event did not go out is offered again."""
    import os

    w = UploadWatcher(tmp_path, stable_s=1000)
    up = tmp_path / "mission-c"
    up.mkdir()
    (up / "cloud.las").write_bytes(b"broken")
    (up / MARKER).touch()
    assert _announce(w, 0) == [up]
    (up / "cloud.las").write_bytes(b"fixed!")  # same size, new content
    os.utime(up / MARKER, ns=(1, 2_000_000_000_000_000_000))
    assert _announce(w, 1) == [up]
    assert _announce(UploadWatcher(tmp_path, stable_s=1000), 2) == []  # remembered with its fingerprint
    (up / "extra.JPG").write_bytes(b"jpeg")
    restarted = UploadWatcher(tmp_path, stable_s=1000)
    assert restarted.poll(now=3) == [up]  # the event could not be posted: not confirmed
    assert restarted.poll(now=4) == [up]  # so it is offered again
    restarted.confirm(up)
    assert restarted.poll(now=5) == []


def test_state_written_before_fingerprints_is_taken_as_reported(tmp_path) -> None:
    up = tmp_path / "mission-d"
    up.mkdir()
    (up / "cloud.las").write_bytes(b"x")
    (up / MARKER).touch()
    (tmp_path / ".siteline-watch.json").write_text(json.dumps({"reported": ["mission-d"]}))
    assert UploadWatcher(tmp_path, stable_s=0).poll(now=0) == []


def test_upload_event_schema(tmp_path) -> None:
    ev = upload_event(tmp_path / "m1", "demo", "abc")
    assert ev["event"] == UPLOADED and ev["resource"]["prefect.resource.id"] == "siteline.mission.m1"
    assert ev["payload"] == {
        "mission_dir": str((tmp_path / "m1").resolve()),
        "site": "demo",
        "fingerprint": "abc",
    }
    assert upload_event(tmp_path / "m1", "demo", "abc")["id"] == ev["id"]  # the same content, the same event
    assert upload_event(tmp_path / "m1", "demo", "abd")["id"] != ev["id"]
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
    assert hits[0][1]["parameters"] == {
        "scene_id": "{{ event.payload.scene_id }}",
        "reason": "labels v{{ event.payload.version }}",  # the run says why it ran (issue 24)
    }
    assert (
        ev["payload"]["scene_id"] == 3
        and ev["payload"]["version"] == 2
        and ev["resource"]["siteline.site.spec"] == "demo"
    )
