"""What colour a pair's images show: the scenes' RGB when both carry it, else intensity
(percentile-stretched per scene) or an elevation ramp (one stretch for both scenes, so unchanged
ground looks the same in A and B). Resolved per pair from each scene's colour statistics
(siteline.records.scan.ColourStats), recorded with the pair's outputs and the release."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np

from siteline.errors import PairError
from siteline.records.scan import ColourStats

ColourChoice = Literal["auto", "rgb", "intensity", "elevation"]
ColourSource = Literal["rgb", "intensity", "elevation"]
COLOUR_CHOICES: tuple[str, ...] = get_args(ColourChoice)
# the elevation ramp: low -> high, five stops of viridis (perceptually uniform, readable in grey)
RAMP = np.array(
    [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], dtype=np.float64
)


@dataclass(frozen=True)
class ColourPlan:
    """A pair's colour: ``source``, and for intensity each scene's (low, high) stretch, for elevation
    the pair's (low, high) site-local z stretch (metres) used for both scenes; ``why`` says how
    ``auto`` chose."""

    source: ColourSource
    stretch_t1: tuple[float, float] | None = None
    stretch_t2: tuple[float, float] | None = None
    why: str = ""

    @property
    def attribute(self) -> str | None:
        """The tile attribute the colour is made from (None: from the points' z)."""
        return {"rgb": "rgb", "intensity": "intensity", "elevation": None}[self.source]

    def colours(self, side: int, xyz: np.ndarray, values: np.ndarray | None) -> np.ndarray:
        """(N, 3) uint8 colour of scene ``side`` (1 or 2)'s points: their RGB, or their ``values``
        (intensity) or z stretched between this plan's bounds."""
        if self.source == "rgb":
            if values is None:
                raise PairError("an RGB colour plan needs the points' rgb.")
            return values
        lo, hi = (self.stretch_t1 if side == 1 else self.stretch_t2) or (0.0, 1.0)
        data = np.asarray(values if self.source == "intensity" else xyz[:, 2], dtype=np.float64)
        t = np.clip((data - lo) / max(hi - lo, 1e-9), 0.0, 1.0) if len(data) else data
        if self.source == "intensity":
            grey = np.rint(t * 255.0).astype(np.uint8)
            return np.repeat(grey[:, None], 3, axis=1)
        pos = t * (len(RAMP) - 1)
        return np.rint(
            np.stack([np.interp(pos, np.arange(len(RAMP)), RAMP[:, c]) for c in range(3)], axis=1)
        ).astype(np.uint8)

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "stretch_t1": list(self.stretch_t1) if self.stretch_t1 else None,
            "stretch_t2": list(self.stretch_t2) if self.stretch_t2 else None,
            "why": self.why,
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> ColourPlan:
        """From :meth:`to_dict`'s form (a pair's or a release lineage's ``colour``)."""
        source = doc.get("source", "rgb")
        if source not in get_args(ColourSource):
            raise PairError(f"colour source {source!r}: use one of {', '.join(get_args(ColourSource))}.")

        def bounds(v: Any) -> tuple[float, float] | None:
            return (float(v[0]), float(v[1])) if v else None

        return cls(source, bounds(doc.get("stretch_t1")), bounds(doc.get("stretch_t2")), str(doc.get("why", "")))


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
