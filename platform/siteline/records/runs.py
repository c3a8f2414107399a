"""A stage run as the catalog records it with the stage's outputs."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime

from siteline.schema import JSON


@dataclass(frozen=True)
class StageRun:
    """One run of a stage on a subject (``mission:<sha256>``, ``scene:<id>``, ``pair:<id>``,
    ``release:<name>:<version>``) with its parameters, when it started (UTC) and the orchestrator's
    run id (a Prefect flow run), if any."""

    stage: str
    subject: str
    parameters: dict[str, JSON] = field(default_factory=dict)
    started: datetime = field(default_factory=lambda: datetime.now(UTC))
    run_id: str | None = None
