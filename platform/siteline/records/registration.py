"""A scene's co-registration onto the one before it, as recorded in its registration
(``registration["alignment"]``; siteline.register.scene.check_alignment writes it)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

# the six directions of a rigid correction
AXES = ("roll", "pitch", "yaw", "x", "y", "z")


@dataclass(frozen=True)
class Alignment:
    """How a scene lines up with the previous one. against_scene: that scene's id. translation_m /
    rotation_deg: the correction found; applied: whether ingest moved the scene by it. residual_m:
    RMS point-to-plane distance on the stable surfaces; residual_xy_m: RMS horizontal distance on the
    structure (None where none was matched). axes: per direction, what fixed it, or None when nothing
    did (recorded before directions were told apart: empty). correction: the 4 x 4 matrix
    (previous scene from this one, site-local metres)."""

    against_scene: int | None
    translation_m: float
    rotation_deg: float
    applied: bool
    residual_m: float
    residual_xy_m: float | None = None
    axes: Mapping[str, str | None] = field(default_factory=dict)
    correction: tuple[tuple[float, ...], ...] = ()
    accepted: bool = True

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> Alignment:
        return cls(
            doc.get("against_scene"),
            float(doc.get("translation_m", 0.0)),
            float(doc.get("rotation_deg", 0.0)),
            bool(doc.get("applied", False)),
            float(doc.get("residual_m", float("inf"))),
            doc.get("residual_xy_m"),
            dict(doc.get("axes") or {}),
            tuple(tuple(float(v) for v in row) for row in doc.get("correction") or ()),
            bool(doc.get("accepted", True)),
        )

    @property
    def free(self) -> list[str]:
        """The directions nothing fixed (none for a record made before directions were told apart)."""
        return [a for a in AXES if a in self.axes and self.axes[a] is None]

    def summary(self) -> str:
        """One line: the correction, applied or not, the residuals, what fixed each direction and
        which nothing fixed (for those no residual is claimed)."""
        how = "applied" if self.applied else "recorded, not applied"
        text = f"ICP moves it {self.translation_m:.3f} m ({how}), residual on stable surfaces {self.residual_m:.3f} m"
        if self.residual_xy_m is not None:
            text += f", {self.residual_xy_m:.3f} m across on structure"
        by: dict[str, list[str]] = {}
        for axis in AXES:
            if axis in self.axes and self.axes[axis] is not None:
                by.setdefault(str(self.axes[axis]), []).append(axis)
        text += "".join(f"; {', '.join(a)} fixed by {w}" for w, a in by.items())
        if self.free:
            them = "it" if len(self.free) == 1 else "them"
            text += (
                f"; {', '.join(self.free)} NOT CHECKED: too little surface or structure in the scenes fixes "
                f"{them}, so an offset there is neither found nor corrected"
            )
        return text


def alignment_of(registration: Mapping[str, Any] | None) -> Alignment | None:
    """The co-registration of a scene's registration record, None when it has none (a first scene)."""
    doc = (registration or {}).get("alignment")
    return Alignment.from_dict(doc) if doc else None
