"""Stage-run records: what ran on which subject, with which parameters, and how it ended.

Library stages write their own ``completed`` record in the transaction that commits their outputs
(stamped with the orchestrator's run id when one is given); an orchestrator records a failure with
:func:`record_failure` in a transaction of its own, so the catalog shows the failed stage while the
stage itself left nothing half-written. Functions take a session; the caller owns the transaction.

Subjects name what a stage ran on, one scheme for library and orchestrator alike: ``mission:<path>``
before a mission is hashed and ``mission:<sha256>`` after, ``scene:<id>``, ``pair:<id>``,
``release:<name>`` before a version is chosen and ``release:<name>:<version>`` after.
"""

from __future__ import annotations

from datetime import UTC, datetime

import sqlalchemy as sa
from sqlalchemy.orm import Session

from siteline.catalog.models import StageRun as StageRunRow
from siteline.records.runs import StageRun


def _row(run: StageRun, status: str, error: BaseException | None = None) -> StageRunRow:
    return StageRunRow(
        stage=run.stage,
        subject=run.subject,
        status=status,
        parameters=run.parameters,
        started_at=run.started,
        finished_at=datetime.now(UTC),
        error_text=None if error is None else f"{type(error).__name__}: {error}"[:4000],
        orchestrator_run_id=run.run_id,
    )


def add_completed(session: Session, run: StageRun) -> None:
    """Add a ``completed`` row for ``run`` to the caller's transaction (the one committing its outputs)."""
    session.add(_row(run, "completed"))


def record_failure(session: Session, run: StageRun, error: BaseException) -> int:
    """Record a failed run of a stage; returns its id."""
    row = _row(run, "failed", error)
    session.add(row)
    session.flush()
    return row.id


def stage_runs(
    session: Session, subject: str | None = None, stage: str | None = None
) -> list[dict[str, object]]:
    """Stage runs (optionally of one subject or stage), oldest first, as dicts."""
    q = sa.select(StageRunRow).order_by(StageRunRow.started_at, StageRunRow.id)
    if subject:
        q = q.where(StageRunRow.subject == subject)
    if stage:
        q = q.where(StageRunRow.stage == stage)
    return [
        {
            "id": r.id,
            "stage": r.stage,
            "subject": r.subject,
            "status": r.status,
            "started_at": r.started_at,
            "finished_at": r.finished_at,
            "error": r.error_text,
            "run_id": r.orchestrator_run_id,
            "parameters": r.parameters,
        }
        for r in session.execute(q).scalars()
    ]
