"""What colour a pair's images show: the scenes' RGB when both carry it, else intensity
(percentile-stretched per scene) or an elevation ramp (one stretch for both scenes, so unchanged
ground looks the same in A and B). Resolved per pair from each scene's colour statistics
(siteline.records.scan.ColourStats), recorded with the pair's outputs and the release."""

from __future__ import annotations

from siteline.errors import PairError
from siteline.records.pairs import COLOUR_CHOICES, ColourPlan
from siteline.records.scan import ColourStats


def _rgb_state(stats: ColourStats | None) -> str:
    return "varies" if stats is None else stats.rgb  # scanned before colour was judged: its RGB


def resolve_colour(
    choice: str, t1: tuple[int, ColourStats | None], t2: tuple[int, ColourStats | None]
) -> ColourPlan:
    """The colour of a pair of scenes ((id, colour statistics) each) for ``choice``: ``auto`` takes
    RGB when both scenes' RGB varies, else intensity when both scenes' intensity varies, else
    elevation; an explicit choice the data cannot give is a :class:`PairError` naming the scene."""
    if choice not in COLOUR_CHOICES:
        raise PairError(f"colour {choice!r}: use one of {', '.join(COLOUR_CHOICES)}.")
    scenes = (t1, t2)
    flat_rgb = [f"scene {sid} ({_rgb_state(st)})" for sid, st in scenes if _rgb_state(st) != "varies"]
    flat_i = [f"scene {sid}" for sid, st in scenes if st is not None and st.intensity_range is None]
    if choice == "rgb" or (choice == "auto" and not flat_rgb):
        if flat_rgb:
            raise PairError(
                f"colour rgb: {' and '.join(flat_rgb)} carry no colour; use --colour intensity or "
                "elevation (or auto)."
            )
        return ColourPlan("rgb", why="both scenes carry RGB" if choice == "auto" else "asked for")
    stats = [st for _, st in scenes]
    if choice == "intensity" or (choice == "auto" and not flat_i and all(stats)):
        if flat_i or not all(stats):
            raise PairError(
                f"colour intensity: {' and '.join(flat_i) or 'a scene'} has constant or unknown intensity; "
                "use --colour elevation (or auto)."
            )
        s1, s2 = (st.intensity_range for st in stats)  # type: ignore[union-attr]
        why = f"no RGB in {' and '.join(flat_rgb)}" if choice == "auto" else "asked for"
        return ColourPlan("intensity", s1, s2, why)
    zs = [st.z_range_m for st in stats if st is not None]
    z = (min(r[0] for r in zs), max(r[1] for r in zs)) if zs else (0.0, 1.0)
    why = "asked for" if choice == "elevation" else f"no RGB in {' and '.join(flat_rgb)}, no intensity in " + (
        " and ".join(flat_i) or "a scene"
    )
    return ColourPlan("elevation", z, z, why)
