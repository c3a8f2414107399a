"""Named speed/accuracy presets for `--preset` (applied by siteline.release.knobs), chosen from the Pareto front
of the old sweep (against a rendered truth) and checked against the analytic truth of `siteline bench
trade` (docs/performance.md: at 1000 points/m2 a 1/8 frame scores changed-class F1 0.986-0.988 for LOD
factors 1-2, a 1/4 frame 0.994). The F1 figures below are the old sweep's.

Scale is relative to the cameras' image size (the paper's 1/8 of a 5645 x 4082 undistorted image is
``scale=0.125`` on real missions).
"""

from __future__ import annotations

PRESETS: dict[str, dict] = {
    # on the front at the cheap end (1000 points/m2): 3 px points at LOD factor 1.41 read 11k points
    # per view at 92.7 % coverage, mask F1 against the truth 0.934 (LOD 2 would drop coverage to 74 %)
    "fast": {"scale": 0.125, "point_size_px": 3, "lod_factor": 1.41, "radius_multiplier": 2.5},
    # twice the resolution, LOD factor 1 (coverage within a point of reading everything): F1 0.937,
    # coverage 96.2 %, 73k points per view
    "balanced": {"scale": 0.25, "point_size_px": 3, "lod_factor": 1.0, "radius_multiplier": 2.5},
    # four times the resolution of fast: the finest masks (F1 0.964 at 10 points/m2)
    "exact": {"scale": 0.5, "point_size_px": 3, "lod_factor": 1.0, "radius_multiplier": 2.5},
}
