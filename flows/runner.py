"""The task runner comes from configuration; the flow code is the same for all of them.

``SITELINE_TASK_RUNNER``: ``threads`` (default), ``processes``, or ``dask``; ``SITELINE_DASK_ADDRESS``
points at a running scheduler (``tcp://host:8786``), else a LocalCluster is started.
``SITELINE_TASK_WORKERS``: workers for threads/processes (default 2).
"""

from __future__ import annotations

import os


def task_runner():  # noqa: ANN201
    kind = os.environ.get("SITELINE_TASK_RUNNER", "threads").strip().lower()
    workers = int(os.environ.get("SITELINE_TASK_WORKERS", "2"))
    if kind == "threads":
        from prefect.task_runners import ThreadPoolTaskRunner

        return ThreadPoolTaskRunner(max_workers=workers)
    if kind == "processes":
        from prefect.task_runners import ProcessPoolTaskRunner

        return ProcessPoolTaskRunner(max_workers=workers)
    if kind == "dask":
        from prefect_dask import DaskTaskRunner

        address = os.environ.get("SITELINE_DASK_ADDRESS")
        if address:
            return DaskTaskRunner(address=address)
        return DaskTaskRunner(
            cluster_kwargs={
                "n_workers": workers,
                "threads_per_worker": 1,
                "host": "127.0.0.1",
                "dashboard_address": None,
            }
        )
    raise ValueError(f"SITELINE_TASK_RUNNER={kind!r}: use threads, processes or dask.")
