"""The task runner comes from configuration (``siteline.config``: ``SITELINE_TASK_RUNNER``,
``SITELINE_TASK_WORKERS``, ``SITELINE_DASK_ADDRESS``); the flow code is the same for all of them."""

from __future__ import annotations

from typing import Any

from prefect.task_runners import TaskRunner

from siteline.config import load_settings


def task_runner() -> TaskRunner[Any]:
    settings = load_settings()
    kind, workers = settings.task_runner, settings.task_workers
    if kind == "threads":
        from prefect.task_runners import ThreadPoolTaskRunner

        return ThreadPoolTaskRunner(max_workers=workers)
    if kind == "processes":
        from prefect.task_runners import ProcessPoolTaskRunner

        return ProcessPoolTaskRunner(max_workers=workers)
    from prefect_dask import DaskTaskRunner

    if settings.dask_address:
        return DaskTaskRunner(address=settings.dask_address)
    return DaskTaskRunner(
        cluster_kwargs={
            "n_workers": workers,
            "threads_per_worker": 1,
            "host": "127.0.0.1",
            "dashboard_address": None,
        }
    )
