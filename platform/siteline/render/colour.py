"""What colour a pair's images show: the scenes' RGB when both carry it, else the height above the
pair's ground on a ramp (0-25 m, the same for every pair); eye-dome lighting when asked; intensity
(percentile-stretched per scene) and an elevation ramp (one stretch for both scenes) when asked.
Resolved per pair from each scene's colour statistics (siteline.records.scan.ColourStats), recorded
with the pair's outputs and the release. bench/legible.py measured the choice on a LiDAR-only forest."""

from __future__ import annotations

from dataclasses import replace

from siteline.errors import PairError
from siteline.records.enums import COLOUR_CHOICES, SHADING_CHOICES
from siteline.records.pairs import HEIGHT_RANGE_M, ColourPlan
from siteline.records.scan import ColourStats


def _rgb_state(stats: ColourStats | None) -> str:
    return "varies" if stats is None else stats.rgb  # scanned before colour was judged: its RGB


def resolve_colour(
    choice: str, t1: tuple[int, ColourStats | None], t2: tuple[int, ColourStats | None], shading: str = "none"
) -> ColourPlan:
    """The colour of a pair of scenes ((id, colour statistics) each) for ``choice``: ``auto`` takes
    RGB when both scenes' RGB varies, else the height above the pair's ground on the ramp (the
    renderer is given the ground); ``intensity`` (each scene's stretch) and ``elevation`` (site z) are
    there when asked; an explicit choice the data cannot give is a :class:`PairError` naming the scene.
    ``shading`` ``edl`` adds eye-dome lighting (siteline.render.shading); ``auto`` is none: on the
    LiDAR-only forest of bench/legible.py it lowered how far apart trees and ground look (d' 3.65 ->
    2.27 over the height ramp, 1.23 -> 0.69 over intensity) by darkening every splat's rim."""
    plan = _source(choice, t1, t2)
    if shading not in SHADING_CHOICES:
        raise PairError(f"shading {shading!r}: use one of {', '.join(SHADING_CHOICES)}.")
    if shading == "auto":
        shading = "none"
    return replace(plan, shading=shading)


def _source(
    choice: str, t1: tuple[int, ColourStats | None], t2: tuple[int, ColourStats | None]
) -> ColourPlan:
    if choice not in COLOUR_CHOICES:
        raise PairError(f"colour {choice!r}: use one of {', '.join(COLOUR_CHOICES)}.")
    scenes = (t1, t2)
    flat_rgb = [f"scene {sid} ({_rgb_state(st)})" for sid, st in scenes if _rgb_state(st) != "varies"]
    flat_i = [f"scene {sid}" for sid, st in scenes if st is not None and st.intensity_range is None]
    if choice == "rgb" or (choice == "auto" and not flat_rgb):
        if flat_rgb:
            raise PairError(
                f"colour rgb: {' and '.join(flat_rgb)} carry no colour; use --colour height, intensity or "
                "elevation (or auto)."
            )
        return ColourPlan("rgb", why="both scenes carry RGB" if choice == "auto" else "asked for")
    if choice in ("auto", "height"):
        why = "asked for" if choice == "height" else (
            f"no RGB in {' and '.join(flat_rgb)}: height above the ground, which shows trees, buildings and "
            "plant apart from the ground where intensity and elevation do not (bench/legible.py)"
        )  # fmt: skip
        return ColourPlan("height", HEIGHT_RANGE_M, HEIGHT_RANGE_M, why)
    stats = [st for _, st in scenes]
    if choice == "intensity":
        if flat_i or not all(stats):
            raise PairError(
                f"colour intensity: {' and '.join(flat_i) or 'a scene'} has constant or unknown intensity; "
                "use --colour height or elevation (or auto)."
            )
        s1, s2 = (st.intensity_range for st in stats)  # type: ignore[union-attr]
        return ColourPlan("intensity", s1, s2, "asked for")
    zs = [st.z_range_m for st in stats if st is not None]
    z = (min(r[0] for r in zs), max(r[1] for r in zs)) if zs else (0.0, 1.0)
    return ColourPlan("elevation", z, z, "asked for")
