"""The one progress callback shape of long stages: ``progress(task, amount, total)``.

``task`` names the step ("partitioning", "labels", "renders"); ``amount`` is the work done since the
last call (points, views, bytes); ``total`` the step's total when known, else None. The CLI draws
rich bars from it, the flows update Prefect progress artifacts. Stages take :func:`no_progress` by
default, so they report unconditionally; what happened is logged (``logging``), not reported here.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol


class Progress(Protocol):
    def __call__(self, task: str, amount: int, total: int | None) -> None: ...


def no_progress(task: str, amount: int, total: int | None) -> None:
    """A progress callback that draws nothing."""


def no_step(amount: int, total: int | None = None) -> None:
    """A one-task callback (what :func:`step` returns) that draws nothing."""


def step(progress: Progress, task: str) -> Callable[..., None]:
    """``progress`` bound to one task: ``report(amount, total=None)``."""

    def report(amount: int, total: int | None = None) -> None:
        progress(task, amount, total)

    return report
