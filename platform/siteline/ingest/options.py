"""What a user may set about one ingest."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from siteline.errors import MissionError
from siteline.records.enums import STORAGES, Storage
from siteline.register.planned import SurveyPlan
from siteline.schema import JSON
from siteline.site.crs import parse_z_unit

UNMAPPED_CODES = ("refuse", "ignore")


@dataclass(frozen=True)
class IngestOptions:
    """crs: CRS of a LAS without one (any CRS PROJ knows). z_unit: unit of the LAS z (m, ft, ftUS;
    default: the unit its CRS implies, siteline.site.crs.z_unit_of). storage: ``copy`` (content-addressed
    store) or ``reference``. Thresholds: georegistration RMS (m) and RANSAC inlier distance (m);
    co-registration onto the previous scene: largest ICP correction (m, 3 m: more means a wrong CRS,
    offset or datum) and residual (m) accepted without ``accept_misalignment``; a correction over
    0.25 m is applied to the scene (siteline.register.scene.AlignmentPolicy: construction changes between
    epochs bias ICP by up to 0.16 m on the synthetic site), any correction is recorded.
    captured_at: the capture time (UTC) when the mission cannot tell it (a LAS with no absolute GPS
    time and no photos) or tells it wrong; it overrides the
    photos, the raw folder name and the LAS header, and is recorded as given. plan_cameras: plan the
    scene's cameras from its point cloud (``survey``: camera model, height, overlaps) even when the
    mission has photos; a mission without photos always gets planned cameras. unmapped_codes: a class
    code the site taxonomy does not map is refused (``refuse``, naming the codes) or its points made
    ``ignore`` (``ignore``, recorded in the scan)."""

    crs: str | None = None
    z_unit: str | None = None
    storage: Storage = "copy"
    accept_misalignment: bool = False
    max_georegistration_rms_m: float = 0.1
    ransac_max_error_m: float = 0.5
    max_alignment_translation_m: float = 3.0
    max_alignment_residual_m: float = 0.15
    captured_at: datetime | None = None
    plan_cameras: bool = False
    survey: SurveyPlan = SurveyPlan()
    unmapped_codes: str = "refuse"

    def __post_init__(self) -> None:
        if self.unmapped_codes not in UNMAPPED_CODES:
            raise MissionError(
                f"unmapped codes {self.unmapped_codes!r}: use one of {', '.join(UNMAPPED_CODES)}."
            )
        if self.z_unit is not None:
            parse_z_unit(self.z_unit)
        if self.captured_at is not None and self.captured_at.tzinfo is None:
            raise MissionError(
                f"captured_at {self.captured_at.isoformat()} has no time zone: give one (Z for UTC)."
            )
        if self.storage not in STORAGES:
            raise MissionError(f"storage must be 'copy' or 'reference', got {self.storage!r}.")

    def record(self, site: str) -> dict[str, JSON]:
        """What the stage run records of these options."""
        return {
            "site": site,
            "storage": self.storage,
            "crs": self.crs,
            "z_unit": self.z_unit,
            "accept_misalignment": self.accept_misalignment,
            "captured_at": self.captured_at.isoformat() if self.captured_at else None,
            "plan_cameras": self.plan_cameras,
            "survey": self.survey.to_dict(),
            "unmapped_codes": self.unmapped_codes,
        }
