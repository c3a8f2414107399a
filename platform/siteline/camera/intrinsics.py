"""A pinhole camera's intrinsics (the one record of them: ``Camera.intrinsics`` gives a posed camera's)
and the named capture cameras planned survey cameras take: DJI Zenmuse sensors from DESIGN.md's
facts, or a camera file the user gives."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

from siteline.errors import CameraError
from siteline.schema import JSON


@dataclass(frozen=True)
class Intrinsics:
    """A pinhole camera's intrinsics: image size, focal lengths and principal point (pixels), and the
    name of the capture camera they describe ("" for a camera of no name)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    name: str = ""

    def __post_init__(self) -> None:
        values = (self.width, self.height, self.fx, self.fy, self.cx, self.cy)
        if not all(isinstance(v, int | float) and math.isfinite(v) and v > 0 for v in values):
            raise CameraError(f"camera model {self.name!r}: size and intrinsics must be positive numbers.")

    def ground_footprint_m(self, altitude_m: float) -> tuple[float, float]:
        """(across, along) metres a nadir image covers on flat ground from ``altitude_m`` (image
        width across the flight line, height along it)."""
        return altitude_m * self.width / self.fx, altitude_m * self.height / self.fy

    def to_dict(self) -> dict[str, JSON]:
        return {"name": self.name} | {k: v for k, v in asdict(self).items() if k != "name"}


def _centred(name: str, width: int, height: int, f: float) -> Intrinsics:
    return Intrinsics(width, height, f, f, width / 2.0, height / 2.0, name)


# Zenmuse L2 RGB: 4/3" 5280 x 3956, 24 mm equivalent (the synthetic missions' sensor, siteline.synth);
# Zenmuse P1 with its 35 mm lens: full frame 8192 x 5460 at 4.4 um pixels (35 mm / 4.4 um)
CAMERA_MODELS: dict[str, Intrinsics] = {
    "zenmuse-l2": _centred("zenmuse-l2", 5280, 3956, 3520.0),
    "zenmuse-p1-35mm": _centred("zenmuse-p1-35mm", 8192, 5460, 7955.0),
}
DEFAULT_CAMERA_MODEL = "zenmuse-l2"


def camera_model(name_or_file: str) -> Intrinsics:
    """A named model (``zenmuse-l2``, ``zenmuse-p1-35mm``) or a JSON file of ``width``, ``height``,
    ``fx`` and optionally ``fy``, ``cx``, ``cy`` (pixels); :class:`CameraError` naming what is wrong."""
    if name_or_file in CAMERA_MODELS:
        return CAMERA_MODELS[name_or_file]
    path = Path(name_or_file)
    if not path.is_file():
        raise CameraError(
            f"camera {name_or_file!r} is neither a known model ({', '.join(CAMERA_MODELS)}) nor a file."
        )
    try:
        doc = json.loads(path.read_text())
        width, height, fx = int(doc["width"]), int(doc["height"]), float(doc["fx"])
        fy = float(doc.get("fy", fx))
        cx, cy = float(doc.get("cx", width / 2.0)), float(doc.get("cy", height / 2.0))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise CameraError(
            f"camera file {path}: expected JSON with width, height, fx (and optionally fy, cx, cy) in "
            f"pixels ({exc})."
        ) from exc
    return Intrinsics(width, height, fx, fy, cx, cy, path.name)
