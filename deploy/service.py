"""The service's Prefect objects besides the deployments (prefect.yaml): the global concurrency limits the
flows hold, and the two automations that recover from killed processes without a person. Run by
`deploy/serve.sh` after `prefect deploy`; idempotent (limits are upserted, automations replaced by name).

    python -m deploy.service [--pair-slots N]   (from the repository root)

Recovery: a flow run of a siteline deployment whose heartbeats (PREFECT_FLOWS_HEARTBEAT_FREQUENCY=30,
set by serve.sh) stop for HEARTBEAT_GRACE_S is marked Crashed (deploy/reporter.py then says so on its page); a crashed siteline run is rescheduled
(AwaitingRetry) at most MAX_ATTEMPTS - 1 times, and a worker picks it up again; the flows reuse every
finished output, so a retry redoes only what the killed attempt had not finished.
"""

from __future__ import annotations

import argparse
import os
from datetime import timedelta

from prefect.client.orchestration import get_client
from prefect.client.schemas.objects import StateType
from prefect.events.actions import ChangeFlowRunState
from prefect.events.schemas.automations import AutomationCore, EventTrigger, Posture
from prefect.events.schemas.events import ResourceSpecification

TAG = "siteline"  # every siteline deployment's runs carry it (prefect.yaml)
PAIR_SLOTS, RELEASE_SLOTS = "siteline-pairs", "siteline-release"
# a 30 s heartbeat (the least Prefect allows) missed, and 20 s of margin for a loaded machine: a run is
# known dead 20-50 s after its death
HEARTBEAT_GRACE_S = 50
MAX_ATTEMPTS = 3
SITELINE_RUNS = {"prefect.resource.role": "tag", "prefect.resource.id": f"prefect.tag.{TAG}"}

AUTOMATIONS = [
    AutomationCore(
        name="siteline: crash unresponsive runs",
        description=(
            "Marks a run of a siteline deployment Crashed when its heartbeats stop for "
            f"{HEARTBEAT_GRACE_S} s (its worker or machine died), so it does not stay Running for good; "
            "'siteline: retry crashed runs' then reschedules it."
        ),
        trigger=EventTrigger(
            after={"prefect.flow-run.heartbeat"},
            expect={
                "prefect.flow-run.heartbeat",
                "prefect.flow-run.Completed",
                "prefect.flow-run.Failed",
                "prefect.flow-run.Cancelled",
                "prefect.flow-run.Crashed",
            },
            match=ResourceSpecification({"prefect.resource.id": ["prefect.flow-run.*"]}),
            match_related=ResourceSpecification(SITELINE_RUNS),
            for_each={"prefect.resource.id"},
            posture=Posture.Proactive,
            threshold=1,
            within=timedelta(seconds=HEARTBEAT_GRACE_S),
        ),
        actions=[
            ChangeFlowRunState(
                state=StateType.CRASHED,
                message=f"no heartbeat for {HEARTBEAT_GRACE_S} s: its process or machine died",
            )
        ],
    ),
    AutomationCore(
        name="siteline: retry crashed runs",
        description=(
            f"Reschedules a crashed run of a siteline deployment (up to {MAX_ATTEMPTS} attempts in all); the "
            "flows reuse every finished pair output and release, so the retry finishes the killed work."
        ),
        trigger=EventTrigger(
            expect={"prefect.flow-run.Crashed"},
            match=ResourceSpecification(
                {
                    "prefect.resource.id": ["prefect.flow-run.*"],
                    "prefect.run-count": [str(n) for n in range(MAX_ATTEMPTS)],
                }
            ),
            match_related=ResourceSpecification(SITELINE_RUNS),
            posture=Posture.Reactive,
            threshold=1,
            within=timedelta(0),
        ),
        actions=[
            ChangeFlowRunState(
                state=StateType.SCHEDULED,
                name="AwaitingRetry",
                message="rescheduled by 'siteline: retry crashed runs' after a crash",
            )
        ],
    ),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pair-slots", type=int, default=int(os.environ.get("SITELINE_PAIR_SLOTS", "2")),
                        help="pairs processed at once across every flow run (default 2, or SITELINE_PAIR_SLOTS)")  # fmt: skip
    args = parser.parse_args()
    with get_client(sync_client=True) as client:
        client.upsert_global_concurrency_limit_by_name(PAIR_SLOTS, max(1, args.pair_slots))
        client.upsert_global_concurrency_limit_by_name(RELEASE_SLOTS, 1)
        for automation in AUTOMATIONS:
            for old in client.read_automations_by_name(automation.name):
                client.delete_automation(old.id)
            client.create_automation(automation)
    print(
        f"concurrency limits {PAIR_SLOTS}={max(1, args.pair_slots)}, {RELEASE_SLOTS}=1; automations: "
        + ", ".join(a.name for a in AUTOMATIONS)
    )


if __name__ == "__main__":
    main()
