"""The one progress callback shape of long stages: ``progress(task, amount, total)``.

``task`` names the step ("partitioning", "labels", "renders"); ``amount`` is the work done since the
last call (points, views, bytes); ``total`` the step's total when known, else None. The CLI draws
rich bars from it, the flows update Prefect progress artifacts.
"""

from __future__ import annotations

from typing import Protocol


class Progress(Protocol):
    def __call__(self, task: str, amount: int, total: int | None) -> None: ...
