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
    origin: np.ndarray,
    quantum_m: float,
    planes: np.ndarray,
    out_xyz: np.ndarray,
    out_rows: np.ndarray,
    first_row: int,
    written: int,
) -> int:
    """For each point k of one decoded chunk: its counts row ``local[k]`` of ``counts`` ((C, 3)
    int32) made site-local metres (``origin`` (3,) float64 + counts x ``quantum_m``, as
    siteline.pointpass.dequantise), kept unless ``crossing[k]`` and it lies outside a plane of
    ``planes`` ((P, 4): a x + b y + c z + d >= 0 inside); a kept point is written to
    ``out_xyz[written]`` with ``first_row + k`` in ``out_rows[written]``, and ``written`` grows.
    Returns the new ``written``."""
    n = written
    for k in range(len(local)):
        row = local[k]
        x = origin[0] + np.float64(counts[row, 0]) * quantum_m
        y = origin[1] + np.float64(counts[row, 1]) * quantum_m
        z = origin[2] + np.float64(counts[row, 2]) * quantum_m
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
        out_rows[n] = first_row + k
        n += 1
    return n
