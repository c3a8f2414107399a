"""A scene's statistics: the one typed reader and writer of ``scene.statistics`` in the catalog."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from datetime import datetime

from siteline.records.registration import Registration
from siteline.records.scan import LasScan
from siteline.records.tiling import SceneTiling
from siteline.schema import JSON, json_int, json_object, json_or_none, json_str

# keys the ingest adds beside the scan's own fields
_INGEST_KEYS = ("las_file", "las_sha256", "stable_sample_sha256", "photos", "cameras")


@dataclass(frozen=True)
class SceneStatistics:
    """What ingest and tiling recorded about a scene. scan: the LAS scan (None for a row written
    without one). las_file / las_sha256: the point cloud inside the mission and its hash;
    stable_sample_sha256: the blob of the alignment sample; photos / cameras: counts. tiling: the tile
    store, once tiled. capture_time_source: where the capture time came from (photos, raw folder,
    LAS header, or given).

    The JSON keeps the scan's fields at the top level and the tiling under ``tiles``, as catalogs
    written before this record did."""

    scan: LasScan | None
    las_file: str | None = None
    las_sha256: str | None = None
    stable_sample_sha256: str | None = None
    photos: int = 0
    cameras: int = 0
    tiling: SceneTiling | None = None
    capture_time_source: str | None = None

    def with_tiling(self, tiling: SceneTiling) -> SceneStatistics:
        return replace(self, tiling=tiling)

    def to_json(self) -> dict[str, JSON]:
        doc: dict[str, JSON] = self.scan.to_dict() if self.scan is not None else {}
        doc |= {k: getattr(self, k) for k in _INGEST_KEYS}
        if self.capture_time_source is not None:
            doc["capture_time_source"] = self.capture_time_source
        if self.tiling is not None:
            doc["tiles"] = self.tiling.to_dict()
        return doc

    @classmethod
    def from_json(cls, doc: Mapping[str, JSON] | None) -> SceneStatistics:
        doc = doc or {}
        tiles = json_or_none(json_object, doc.get("tiles"), "tiles")
        return cls(
            scan=LasScan.from_dict(doc) if "point_count" in doc else None,
            las_file=json_or_none(json_str, doc.get("las_file"), "las_file"),
            las_sha256=json_or_none(json_str, doc.get("las_sha256"), "las_sha256"),
            stable_sample_sha256=json_or_none(
                json_str, doc.get("stable_sample_sha256"), "stable_sample_sha256"
            ),
            photos=json_int(doc.get("photos", 0), "photos"),
            cameras=json_int(doc.get("cameras", 0), "cameras"),
            tiling=SceneTiling.from_dict(tiles) if tiles else None,
            capture_time_source=json_or_none(json_str, doc.get("capture_time_source"), "capture_time_source"),
        )


@dataclass(frozen=True)
class SceneView:
    """A scene as the catalog hands it out: its id, site and mission, capture time (UTC), points,
    status, registration record, statistics, and its tile store's address (None: not tiled)."""

    id: int
    site_id: int
    mission_id: int
    capture_time: datetime
    point_count: int
    status: str
    registration: Registration
    statistics: SceneStatistics
    tile_store_uri: str | None = None
