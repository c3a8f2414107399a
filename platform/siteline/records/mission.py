"""A mission as ingest reads it: its files, its manifest hash, and everything checked before anything
is stored."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from datetime import datetime
from pathlib import Path

from siteline.camera.pinhole import Camera
from siteline.records.enums import CameraSource, FileKind, Storage
from siteline.records.registration import Registration
from siteline.records.scan import LasScan
from siteline.schema import JSON


@dataclass(frozen=True)
class FileEntry:
    """One file of a mission: POSIX path relative to the mission folder, size in bytes, sha256, kind."""

    path: str
    size_bytes: int
    sha256: str
    kind: FileKind

    def to_dict(self) -> dict[str, JSON]:
        return asdict(self)


@dataclass(frozen=True)
class MissionManifest:
    """A mission folder's inventory: its root, every file (sorted by path) and the manifest hash that
    identifies the mission (DESIGN.md §1)."""

    root: Path
    entries: tuple[FileEntry, ...]
    sha256: str


@dataclass(frozen=True)
class CheckedMission:
    """Everything ingest read and checked about one mission before the catalog records it: the
    manifest, the name it is known by, the LAS scan and the point cloud's hash, the registered
    cameras (site-local, COLMAP ``cam_from_world``) and their source, the registration record
    (georegistration and alignment), the capture time (UTC) and where it came from, the stable-point
    sample's blob hash, and how the files are kept."""

    manifest: MissionManifest
    name: str
    scan: LasScan
    las_sha256: str
    cameras: Mapping[str, Camera]
    camera_source: CameraSource
    registration: Registration
    capture_time: datetime
    capture_time_source: str
    sample_sha256: str
    storage: Storage


@dataclass(frozen=True)
class LasLocation:
    """Where a scene's point cloud is kept: its mission's storage (``copy``: a blob of the store;
    ``reference``: the original folder at ``root_uri``), the file's path inside the mission, and
    its sha256."""

    storage: Storage
    root_uri: str
    path: str
    sha256: str
