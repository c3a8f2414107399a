"""A scene's registration record: how its cameras were found (COLMAP georegistration, DJI XMP poses,
planned from its points, or none), the survey planned cameras were laid out by, and its
co-registration onto the scene before it (siteline.register writes it; the catalog's
``scene.registration`` column holds its JSON form, read and written only through :class:`Registration`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace

import numpy as np

from siteline.camera.intrinsics import CAMERA_MODELS, DEFAULT_CAMERA_MODEL, Intrinsics
from siteline.camera.pinhole import CameraModel
from siteline.camera.poses import Sim3
from siteline.errors import RegistrationError
from siteline.schema import (
    JSON,
    json_bool,
    json_float,
    json_int,
    json_list,
    json_number,
    json_object,
    json_or_none,
    json_str,
)

# the six directions of a rigid correction
AXES = ("roll", "pitch", "yaw", "x", "y", "z")


@dataclass(frozen=True)
class Alignment:
    """How a scene lines up with the previous one. against_scene: that scene's id. translation_m /
    rotation_deg: the correction found; applied: whether ingest moved the scene by it (it does over
    ``apply_above_m``); accepted: within the alignment policy (or accepted by the user). residual_m:
    RMS point-to-plane distance on the stable surfaces; residual_xy_m / residual_z_m: RMS horizontal
    and vertical distance on the structure (None where none was matched). axes: per direction, what
    fixed it, or None when nothing did (empty for records made before directions were told apart).
    correction: the 4 x 4 matrix (previous scene from this one, site-local metres; its frames named in
    ``correction_frames``). matched / structure_matched: point pairs of each kind; surfaces: which
    stable surfaces were matched; overlap: the share of the sample that overlapped the previous scene;
    degenerate: some direction stayed free; iterations: ICP's."""

    against_scene: int | None
    translation_m: float
    rotation_deg: float
    applied: bool
    residual_m: float
    residual_xy_m: float | None = None
    axes: Mapping[str, str | None] = field(default_factory=dict)
    correction: tuple[tuple[float, ...], ...] = ()
    accepted: bool = True
    residual_z_m: float | None = None
    correction_frames: str | None = None
    matched: int | None = None
    structure_matched: int | None = None
    surfaces: str | None = None
    degenerate: bool | None = None
    iterations: int | None = None
    overlap: float | None = None
    apply_above_m: float | None = None

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> Alignment:
        """From :meth:`to_dict`'s form (a record made before a field existed lacks it)."""

        def number(key: str, default: float | None = None) -> float | None:
            return json_or_none(json_number, doc.get(key, default), key)

        def count(key: str) -> int | None:
            return json_or_none(json_int, doc.get(key), key)

        def text(key: str) -> str | None:
            return json_or_none(json_str, doc.get(key), key)

        axes = json_object(doc.get("axes") or {}, "axes")
        rows = json_list(doc.get("correction") or (), "correction")
        return cls(
            against_scene=count("against_scene"), translation_m=json_number(doc.get("translation_m", 0.0), "translation_m"),
            rotation_deg=json_number(doc.get("rotation_deg", 0.0), "rotation_deg"),
            applied=json_bool(doc.get("applied", False), "applied"),
            residual_m=json_number(doc.get("residual_m", float("inf")), "residual_m"), residual_xy_m=number("residual_xy_m"),
            axes={a: json_or_none(json_str, v, f"axes.{a}") for a, v in axes.items()},
            correction=tuple(tuple(json_float(v, "correction") for v in json_list(row, "correction")) for row in rows),
            accepted=json_bool(doc.get("accepted", True), "accepted"), residual_z_m=number("residual_z_m"),
            correction_frames=text("correction_frames"), matched=count("matched"),
            structure_matched=count("structure_matched"), surfaces=text("surfaces"),
            degenerate=json_or_none(json_bool, doc.get("degenerate"), "degenerate"), iterations=count("iterations"),
            overlap=number("overlap"), apply_above_m=number("apply_above_m"),
        )  # fmt: skip

    def to_dict(self) -> dict[str, JSON]:
        """The JSON form (None-valued optional fields left out; ``free`` named for readers)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["correction"] = [list(row) for row in self.correction]
        out["axes"] = dict(self.axes)
        out = {
            k: v
            for k, v in out.items()
            if v is not None or k in ("against_scene", "residual_xy_m", "residual_z_m")
        }
        return out | ({"free": self.free} if self.axes else {})

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


@dataclass(frozen=True)
class SurveyPlan:
    """How planned cameras are laid out. altitude_m: above the ground under each camera (the 10th
    percentile of the sample's z around it), or None to choose it from the scene (:func:`siteline.register.planned.auto_altitude`);
    forward_overlap / side_overlap: of consecutive images on a line and of neighbouring lines (0-1);
    oblique_pitch_deg: downward tilt of the oblique cameras looking into the area from around its
    edge (0: no oblique pass). clearance_m: how far over the scene's tallest structure an altitude
    chosen from the scene flies (siteline.register.planned.auto_altitude)."""

    camera: Intrinsics = CAMERA_MODELS[DEFAULT_CAMERA_MODEL]
    altitude_m: float | None = None
    forward_overlap: float = 0.7
    side_overlap: float = 0.6
    oblique_pitch_deg: float = 45.0
    clearance_m: float = 15.0

    def __post_init__(self) -> None:
        h = self.altitude_m
        if h is not None and not (math.isfinite(h) and 5.0 <= h <= 1000.0):
            raise RegistrationError(f"planned cameras: altitude {h} m must lie in [5, 1000].")
        for name in ("forward_overlap", "side_overlap"):
            v = getattr(self, name)
            if not 0.0 <= v <= 0.95:
                raise RegistrationError(f"planned cameras: {name} {v} must lie in [0, 0.95].")
        if not (math.isfinite(self.clearance_m) and 0.0 <= self.clearance_m <= 200.0):
            raise RegistrationError(f"planned cameras: clearance {self.clearance_m} m must lie in [0, 200].")
        if not 0.0 <= self.oblique_pitch_deg < 90.0:
            raise RegistrationError(
                f"planned cameras: oblique pitch {self.oblique_pitch_deg} must lie in [0, 90) degrees."
            )

    def to_dict(self) -> dict[str, JSON]:
        doc: dict[str, JSON] = {
            "camera": self.camera.to_dict(), "altitude_m": self.altitude_m,
            "forward_overlap": self.forward_overlap, "side_overlap": self.side_overlap,
            "oblique_pitch_deg": self.oblique_pitch_deg,
        }  # fmt: skip
        if self.clearance_m:  # a survey planned before the clearance existed keeps its JSON
            doc["clearance_m"] = self.clearance_m
        return doc

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON]) -> SurveyPlan:
        cam = json_object(doc["camera"], "camera")
        camera = Intrinsics(
            json_int(cam["width"], "camera.width"),
            json_int(cam["height"], "camera.height"),
            json_number(cam["fx"], "camera.fx"),
            json_number(cam["fy"], "camera.fy"),
            json_number(cam["cx"], "camera.cx"),
            json_number(cam["cy"], "camera.cy"),
            name=json_str(cam.get("name", ""), "camera.name"),
        )
        return cls(
            camera, json_or_none(json_number, doc.get("altitude_m"), "altitude_m"),
            json_float(doc["forward_overlap"], "forward_overlap"),
            json_float(doc["side_overlap"], "side_overlap"),
            json_float(doc["oblique_pitch_deg"], "oblique_pitch_deg"),
            # surveys planned before the clearance existed cleared nothing
            json_float(doc.get("clearance_m", 0.0), "clearance_m"),
        )  # fmt: skip

    def nadir_cameras(self, altitude_m: float, area_m2: float) -> float:
        """About how many nadir cameras cover ``area_m2`` at ``altitude_m`` (the grid's cell is the
        footprint less the overlaps)."""
        across, along = self.camera.ground_footprint_m(altitude_m)
        return area_m2 / (across * (1.0 - self.side_overlap) * along * (1.0 - self.forward_overlap))


@dataclass(frozen=True)
class Registration:
    """How a scene's cameras were found and how it lines up with the scene before it.

    source: ``colmap``, ``xmp``, ``planned`` or ``none``; images: how many cameras it gave; note: why
    (a LiDAR-only mission, cameras planned, or why none could be); planned: False where planning was
    tried and gave none. Planned cameras: over (``site fence`` or ``scene footprint``), the survey and
    why its altitude (``altitude_why``). XMP and COLMAP: camera_models, the distortion each undistorted
    camera came from (pycolmap's model name and parameters, by image). COLMAP: site_from_model (the
    Sim3: scale, 3 x 3 rotation, translation in site-local metres), residuals_m (per image, metres)
    and their rms_m. alignment: the co-registration onto the previous scene (None for a first scene)."""

    source: str
    images: int | None = None
    note: str | None = None
    planned: bool | None = None
    over: str | None = None
    survey: SurveyPlan | None = None
    altitude_why: str | None = None
    camera_models: Mapping[str, CameraModel | None] | None = None
    site_from_model: Sim3 | None = None
    residuals_m: Mapping[str, float] | None = None
    rms_m: float | None = None
    alignment: Alignment | None = None

    @classmethod
    def from_dict(cls, doc: Mapping[str, JSON] | None) -> Registration:
        """From the catalog's JSON form; an empty record (a scene made before registration was
        recorded) reads as source ``unknown``."""
        doc = doc or {}
        survey = json_or_none(json_object, doc.get("survey"), "survey")
        alignment = json_or_none(json_object, doc.get("alignment"), "alignment")
        models = json_or_none(json_object, doc.get("camera_models"), "camera_models")
        sim = json_or_none(json_object, doc.get("site_from_model"), "site_from_model")
        residuals = json_or_none(json_object, doc.get("residuals_m"), "residuals_m")
        return cls(
            source=json_str(doc.get("source", "unknown"), "source"), images=json_or_none(json_int, doc.get("images"), "images"),
            note=json_or_none(json_str, doc.get("note"), "note"), planned=json_or_none(json_bool, doc.get("planned"), "planned"),
            over=json_or_none(json_str, doc.get("over"), "over"),
            survey=SurveyPlan.from_dict(survey) if survey else None,
            altitude_why=json_or_none(json_str, survey.get("altitude_why"), "altitude_why") if survey else None,
            alignment=Alignment.from_dict(alignment) if alignment else None,
            camera_models={k: CameraModel.from_dict(json_object(m, f"camera_models.{k}")) if m else None for k, m in models.items()} if models is not None else None,
            site_from_model=Sim3("site", "model", json_float(sim["scale"], "scale"), np.asarray(sim["rotation"], np.float64),
                                 np.asarray(sim["translation"], np.float64)) if sim is not None else None,
            residuals_m={k: json_number(v, f"residuals_m.{k}") for k, v in residuals.items()} if residuals is not None else None,
            rms_m=json_or_none(json_number, doc.get("rms_m"), "rms_m"),
        )  # fmt: skip

    def to_dict(self) -> dict[str, JSON]:
        """The JSON form the catalog keeps (fields that do not apply left out)."""
        out: dict[str, JSON] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None or f.name == "altitude_why":
                continue
            if f.name == "survey":
                value = self.survey_record()
            elif f.name == "alignment":
                value = value.to_dict()
            elif f.name == "camera_models":
                value = {k: m.to_dict() if m else None for k, m in value.items()}
            elif f.name == "site_from_model":
                value = {
                    "scale": float(value.scale),
                    "rotation": value.R.tolist(),
                    "translation": value.t.tolist(),
                }
            out[f.name] = value
        return out

    def survey_record(self) -> dict[str, JSON] | None:
        """How planned cameras were flown and why at that altitude (None: photo cameras)."""
        if self.survey is None:
            return None
        return self.survey.to_dict() | ({"altitude_why": self.altitude_why} if self.altitude_why else {})

    @property
    def correction(self) -> tuple[tuple[float, ...], ...] | None:
        """The co-registration ingest applied to the scene (4 x 4 site-local, previous scene from
        this one), None when none was applied."""
        a = self.alignment
        return a.correction if a is not None and a.applied else None

    def aligned(self, alignment: Alignment) -> Registration:
        """This record with its co-registration."""
        return replace(self, alignment=alignment)
