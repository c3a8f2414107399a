"""Compiled loops of a view's tile read: the points a view keeps, taken out of the decoded chunks,
made metres and tested against the frustum in one pass (numpy made four: gather, dequantise, test,
select), written where the read's output wants them."""

from __future__ import annotations

import numpy as np

from siteline.pointpass import kernel


@kernel
def place_points(
    counts: np.ndarray,
    local: np.ndarray,
    crossing: np.ndarray,
    frame: np.ndarray,
    planes: np.ndarray,
    out_xyz: np.ndarray,
    out_rows: np.ndarray,
    written: int,
) -> int:
    """For each point k of one decoded chunk: its counts row ``local[k]`` of ``counts`` ((C, 3)
    int32) made site-local metres (``frame``: the tile's origin (3 values, float64) and the quantum
    in metres; origin + counts x quantum, as siteline.pointpass.dequantise), kept unless
    ``crossing[k]`` and it lies outside a plane of ``planes`` ((P, 4): a x + b y + c z + d >= 0
    inside); a kept point is written to ``out_xyz[written]`` with ``k`` in ``out_rows[written]``, and
    ``written`` grows. Returns the new ``written``."""
    n = written
    quantum = frame[3]
    for k in range(len(local)):
        row = local[k]
        x = frame[0] + np.float64(counts[row, 0]) * quantum
        y = frame[1] + np.float64(counts[row, 1]) * quantum
        z = frame[2] + np.float64(counts[row, 2]) * quantum
        if crossing[k]:
            inside = True
            for p in range(planes.shape[0]):
                if x * planes[p, 0] + y * planes[p, 1] + z * planes[p, 2] + planes[p, 3] < 0.0:
                    inside = False
                    break
            if not inside:
                continue
        out_xyz[n, 0] = x
        out_xyz[n, 1] = y
        out_xyz[n, 2] = z
        out_rows[n] = k
        n += 1
    return n
