"""What a tiling may use besides the file: one record passed from the tile stage to the writer."""

from __future__ import annotations

from concurrent.futures import Executor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from siteline.pointpass.partition import PartitionCache


@dataclass(frozen=True)
class TilingResources:
    """``workers``: local processes that cut and write (``executor``, a Dask cluster's say, writes the
    tiles instead, its workers sharing the store). ``batch_points``: a tile of more points is
    levelled and ordered in batches of its blocks, so a worker's memory stays about 200 bytes x
    ``batch_points`` whatever the density (the same store; None: the writer's default, or the
    settings' in the tile stage). ``scratch``: a local folder for the partition, on the file system
    of ``partitions`` for a kept one to be taken over (None: the system's temporary folder).
    ``partitions``: where ingest keeps partitions (None: none is looked for)."""

    workers: int = 2
    batch_points: int | None = None
    executor: Executor | None = None
    scratch: Path | None = None
    partitions: PartitionCache | None = None

    def completed(self, **defaults: Any) -> TilingResources:
        """These resources with each field still None taken from ``defaults``."""
        return replace(self, **{k: v for k, v in defaults.items() if getattr(self, k) is None})
