"""The task runner comes from configuration (``siteline.config``: ``SITELINE_TASK_RUNNER``,
``SITELINE_TASK_WORKERS``, ``SITELINE_DASK_ADDRESS``); the flow code is the same for all of them."""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import Executor
from contextlib import contextmanager
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


@contextmanager
def cluster_executor() -> Iterator[Executor | None]:
    """In a task running on a Dask worker: an executor over the whole cluster, so the task's work
    (a scene's tiles) is spread over every worker; the task secedes from its worker's thread while
    it waits, so its own slot takes work too. None anywhere else (the library's own process pool)."""
    try:
        from distributed import get_worker, worker_client

        get_worker()
    except (ImportError, ValueError):  # not on a Dask worker
        yield None
        return
    with worker_client() as client:
        yield client.get_executor()
