"""``siteline watch``: notice completed uploads and announce them to the Prefect API.

Events go out the way an external uploader would send them: ``POST <PREFECT_API_URL>/events`` with a
JSON list of events (so this module needs no Prefect import). The ingest deployment's trigger starts
a run for each ``siteline.mission.uploaded`` event.
"""

from __future__ import annotations

import os
import time
import uuid
from datetime import UTC, datetime
from pathlib import Path

import typer

from siteline.cli.common import console
from siteline.errors import ConfigError
from siteline.ingest.watch import MARKER, UploadWatcher

UPLOADED = "siteline.mission.uploaded"


def upload_event(mission_dir: Path, site: str, fingerprint: str = "") -> dict:
    """The event announcing a completed upload (Prefect's event schema); its id is derived from the
    folder and its content's fingerprint, so announcing the same content twice sends the same event."""
    key = f"{mission_dir.resolve()}:{fingerprint}"
    return {
        "id": str(uuid.uuid5(uuid.NAMESPACE_URL, key)) if fingerprint else str(uuid.uuid4()),
        "occurred": datetime.now(UTC).isoformat(),
        "event": UPLOADED,
        "resource": {
            "prefect.resource.id": f"siteline.mission.{mission_dir.name}",
            "siteline.site.spec": site,
        },
        "payload": {"mission_dir": str(mission_dir.resolve()), "site": site, "fingerprint": fingerprint},
        "related": [],
    }


def post_events(api_url: str, events: list[dict]) -> None:
    import httpx

    try:
        r = httpx.post(f"{api_url.rstrip('/')}/events", json=events, timeout=10)
        r.raise_for_status()
    except httpx.HTTPError as exc:
        raise ConfigError(f"cannot post events to the Prefect API at {api_url}: {exc}") from exc


def watch(
    folder: Path = typer.Argument(..., help="Folder whose sub-folders are mission uploads."),
    site: str = typer.Option(..., "--site", help="Site the uploads belong to."),
    stable_seconds: float = typer.Option(
        30.0, "--stable-seconds", help=f"Complete when unchanged this long (or when {MARKER} appears)."
    ),
    interval_seconds: float = typer.Option(5.0, "--interval-seconds", help="Polling period."),
    api_url: str | None = typer.Option(None, "--api-url", help="Prefect API (default: PREFECT_API_URL)."),
    once: bool = typer.Option(False, "--once", help="Poll once and exit."),
) -> None:
    """Emit one siteline.mission.uploaded event per completed upload in FOLDER."""
    url = api_url or os.environ.get("PREFECT_API_URL")
    if not url:
        raise ConfigError(
            "no Prefect API: set PREFECT_API_URL (e.g. http://127.0.0.1:4200/api) or pass --api-url."
        )
    watcher = UploadWatcher(folder, stable_s=stable_seconds)
    console.print(
        f"watching {folder} for uploads to site {site} (complete after {stable_seconds:g} s unchanged or {MARKER})"
    )
    while True:
        for mission in watcher.poll():
            try:
                post_events(url, [upload_event(mission, site, watcher.pending_fingerprint(mission))])
            except ConfigError as exc:  # the API is down: announce it on a later poll
                console.print(f"upload complete: {mission.name}, not announced yet: {exc}")
                continue
            watcher.confirm(mission)
            console.print(f"upload complete: {mission.name} -> {UPLOADED}")
        if once:
            return
        time.sleep(interval_seconds)
