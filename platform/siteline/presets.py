"""Named speed/accuracy presets for `siteline release build --preset`, chosen from the Pareto front
that `siteline bench trade` measured (docs/performance.md has the table and the plots).

Scale is relative to the cameras' image size (the paper's 1/8 of a 5645 x 4082 undistorted image is
``scale=0.125`` on real missions).
"""

from __future__ import annotations

from siteline.errors import ReleaseError
from siteline.pairs import PairParams

PRESETS: dict[str, dict] = {
    # on the front at the cheap end: 3 px points keep coverage (85 %), LOD factor 2 reads a third fewer
    # points; mask F1 against the truth 0.91
    "fast": {"scale": 0.125, "point_size_px": 3, "lod_factor": 2.0, "radius_multiplier": 2.5},
    # twice the resolution, every level a pixel can use: F1 0.93, coverage 74 %
    "balanced": {"scale": 0.25, "point_size_px": 3, "lod_factor": 1.0, "radius_multiplier": 2.5},
    # four times the resolution of fast: F1 0.94, coverage 58 % (1 px points would drop it to 24 %)
    "exact": {"scale": 0.5, "point_size_px": 3, "lod_factor": 1.0, "radius_multiplier": 2.5},
}


def preset_params(name: str, base: PairParams | None = None) -> PairParams:
    """``base`` (or the defaults) with the preset's knobs."""
    if name not in PRESETS:
        raise ReleaseError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}.")
    doc = (base or PairParams()).to_dict() | PRESETS[name]
    return PairParams.from_dict(doc)
