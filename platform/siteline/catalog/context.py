"""What a stage entry runs with: the catalog it records in, the settings (home, store, workers), where
it reports progress, and the orchestrator's run id its stage runs are recorded under."""

from __future__ import annotations

from dataclasses import dataclass

from siteline.catalog import Catalog
from siteline.config import Settings
from siteline.progress import Progress, no_progress


@dataclass(frozen=True)
class StageContext:
    """catalog, settings; progress: the callback a stage reports its steps to (no_progress: none);
    run_id: the orchestrator's run (a Prefect flow run id) recorded with each stage run, or None."""

    catalog: Catalog
    settings: Settings
    progress: Progress = no_progress
    run_id: str | None = None
