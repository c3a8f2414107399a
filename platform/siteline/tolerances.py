"""Boundary decisions that give one answer at every coordinate magnitude (DESIGN.md §2, §5).

Every yes/no decision on a float (inside the fence, far enough from a surface, enough coverage) is
taken on site-local values, which agree across magnitudes only to within float64 rounding of the
origin subtraction and of georegistration (~1e-9 m to ~1e-6 m). A value that lands within the
tolerance of its threshold therefore gets one documented answer instead of whichever side the
rounding fell on:

- lengths (fence, clearance, height above ground): ``LENGTH_TOL_M`` = 0.1 mm, a tenth of the tile
  quantum. On the boundary within the tolerance counts as inside the fence / far enough / high enough:
  the view is *kept*.
- ratios of pixel counts (coverage, valid fraction): ``RATIO_TOL`` = 1e-9, far below one pixel in any
  image (1 / (5645 x 4082) = 4.3e-8). Equal to the threshold within the tolerance *passes*.

Camera poses entering view generation are snapped to ``POSE_CENTER_QUANTUM_M`` and
``POSE_ROTATION_QUANTUM`` so that georegistration noise far below a pixel (3.5e-7 m measured between
the same site at origin 1e3 m and 8.4e6 m) cannot change a single float32 render.
"""

from __future__ import annotations

import numpy as np

LENGTH_TOL_M = 1e-4
RATIO_TOL = 1e-9
# 0.1 mm: 3e-4 px at 1/8 of a 5645 px camera 30 m away; far above registration noise (~1e-6 m)
POSE_CENTER_QUANTUM_M = 1e-4
# rotation matrix entries: 1e-6 rad-ish, 1e-4 px at 1/8 scale
POSE_ROTATION_QUANTUM = 1e-6


def at_least(value: np.ndarray | float, threshold: float, tol: float) -> np.ndarray | bool:
    """``value >= threshold``, where a value within ``tol`` below the threshold also passes."""
    return np.asarray(value) >= threshold - tol


def snap(values: np.ndarray, quantum: float) -> np.ndarray:
    """``values`` (float64) rounded to the nearest multiple of ``quantum``."""
    return np.round(np.asarray(values, dtype=np.float64) / quantum) * quantum
