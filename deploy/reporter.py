"""Says on a run's own page why it stopped: for every siteline run that crashed (its heartbeats stopped:
its process or machine died; or its process exited) or was rescheduled, a markdown artifact on the run
(key ``why-<run id>``) and the run's progress bar description say so in words, a few seconds after the
crash automation (deploy/service.py) marks it. Supervised by `deploy/serve.sh`; restarting it
repeats nothing already reported.

    python -m deploy.reporter [--every 3]   (from the repository root)
"""

from __future__ import annotations

import argparse
import re
import time
from datetime import UTC, datetime, timedelta
from uuid import UUID

from prefect.client.orchestration import SyncPrefectClient, get_client
from prefect.client.schemas.actions import ArtifactCreate, ArtifactUpdate
from prefect.client.schemas.filters import (
    ArtifactFilter,
    ArtifactFilterFlowRunId,
    ArtifactFilterKey,
    ArtifactFilterType,
)
from prefect.events.filters import EventFilter, EventNameFilter, EventOccurredFilter, EventRelatedFilter

from deploy.service import MAX_ATTEMPTS, TAG
from siteline.previews.markdown import RunEvent, stopped_markdown

WATCHED = ("prefect.flow-run.Crashed", "prefect.flow-run.AwaitingRetry")
LOOK_BACK = timedelta(hours=6)
STATE_MARK = re.compile(r"<!-- state ([0-9a-f-]{36}) -->")


def _events(client: SyncPrefectClient, since: datetime) -> list:
    page = client.read_events(
        EventFilter(
            occurred=EventOccurredFilter(since=since, until=datetime.now(UTC) + timedelta(minutes=1)),
            event=EventNameFilter(name=list(WATCHED)),
            related=EventRelatedFilter(id=[f"prefect.tag.{TAG}"]),
        ),
        limit=50,  # the most the API gives a page
    )
    events = list(page.events)
    while page.next_page and len(events) < 2000:
        page = client.read_events_page(str(page.next_page))
        events += page.events
    return sorted(events, key=lambda e: e.occurred)


def _reported(client: SyncPrefectClient, run_id: UUID) -> set[str]:
    """The state ids the run's why-artifact already tells of."""
    arts = client.read_artifacts(
        artifact_filter=ArtifactFilter(key=ArtifactFilterKey(any_=[f"why-{run_id}"])), limit=20
    )
    return {m for a in arts for m in STATE_MARK.findall(str(a.data or ""))}


def _progress(client: SyncPrefectClient, run_id: UUID):  # noqa: ANN202 (a Prefect Artifact or None)
    arts = client.read_artifacts(
        artifact_filter=ArtifactFilter(
            flow_run_id=ArtifactFilterFlowRunId(any_=[run_id]), type=ArtifactFilterType(any_=["progress"])
        ),
        limit=50,
    )
    return max(arts, key=lambda a: a.created, default=None)


def report(client: SyncPrefectClient, since: datetime, done: set[str]) -> list[str]:
    """Report every crash and reschedule since ``since`` not in ``done`` (state ids; updated); the
    runs reported."""
    by_run: dict[UUID, list] = {}
    for e in _events(client, since):
        by_run.setdefault(UUID(e.resource.id.removeprefix("prefect.flow-run.")), []).append(e)
    out = []
    for run_id, events in by_run.items():
        ids = {str(e.id) for e in events}
        if ids <= done:
            continue
        done |= _reported(client, run_id)
        if ids <= done:
            continue
        history = [
            RunEvent(e.occurred.astimezone(UTC), e.resource.get("prefect.state-name", ""),
                     e.resource.get("prefect.state-message", "") or "", int(e.resource.get("prefect.run-count", "0") or 0))
            for e in events
        ]  # fmt: skip
        name = events[-1].resource.get("prefect.resource.name", str(run_id))
        bar = _progress(client, run_id)
        where = None
        if bar is not None:
            where = f"{bar.data:.0f} % done" + (f" ({bar.description})" if bar.description else "")
        text = stopped_markdown(name, history, where, MAX_ATTEMPTS)
        marks = "".join(f"<!-- state {i} -->" for i in sorted(ids))
        first_line = text.splitlines()[2]
        client.create_artifact(
            ArtifactCreate(
                key=f"why-{run_id}",
                type="markdown",
                data=text + marks,
                flow_run_id=run_id,
                description=first_line[:250],
            )
        )
        if bar is not None:
            last = history[-1]
            note = "rescheduled after a crash" if last.state == "AwaitingRetry" else "crashed"
            client.update_artifact(
                bar.id,
                ArtifactUpdate(description=f"stopped at {bar.data:.0f} %: {note}: {last.message}"[:250]),
            )
        done |= ids
        out.append(name)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--every", type=float, default=3.0, help="seconds between looks (default 3)")
    args = parser.parse_args()
    done: set[str] = set()
    since = datetime.now(UTC) - LOOK_BACK
    with get_client(sync_client=True) as client:
        while True:
            try:
                for name in report(client, since, done):
                    print(f"{datetime.now(UTC):%H:%M:%S} reported why {name} stopped", flush=True)
            except Exception as exc:  # the server restarting, say: try again at the next look
                print(f"{datetime.now(UTC):%H:%M:%S} could not look at the runs: {exc}", flush=True)
            time.sleep(args.every)


if __name__ == "__main__":
    main()
