"""Reading a mission folder's contents: which point cloud, which photos, which COLMAP model, and when
it was captured (DESIGN.md §9)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from datetime import UTC, date, datetime, timedelta
from pathlib import Path

from siteline.errors import MissionError, PhotoError
from siteline.photos import PhotoMeta, read_photo_meta
from siteline.records.mission import FileEntry
from siteline.records.scan import LasScan

PREFERRED_LAS = ("lidars/terra_las/cloud_merged.las", "lidars/terra_las/cloud_merged.laz")
RAW_FOLDER = re.compile(r"^DJI_(\d{12})_\d{3}_")
# GPS time runs ahead of UTC by the leap seconds since 1980
GPS_UTC_OFFSET_S = 18


def choose_las(entries: Sequence[FileEntry], root: Path) -> FileEntry:
    las = [e for e in entries if e.kind == "las"]
    if not las:
        raise MissionError(f"mission {root} holds no LAS/LAZ point cloud (expected {PREFERRED_LAS[0]}).")
    for pref in PREFERRED_LAS:
        for e in las:
            if e.path.lower() == pref:
                return e
    if len(las) > 1:
        raise MissionError(
            f"mission {root} holds several point clouds ({', '.join(e.path for e in las)}) and none is "
            f"{PREFERRED_LAS[0]}: keep one."
        )
    return las[0]


def read_photos(entries: Sequence[FileEntry], root: Path) -> dict[str, PhotoMeta]:
    out = {}
    for e in entries:
        if e.kind == "photo":
            meta = read_photo_meta(root / e.path)
            if not meta.has_orientation:
                raise PhotoError(f"photo {root / e.path} has a position but no gimbal angles.")
            out[e.path] = meta
    return out


def colmap_dir(entries: Sequence[FileEntry], root: Path) -> Path | None:
    dirs = sorted({str(Path(e.path).parent) for e in entries if e.kind == "colmap"})
    model_dirs = [
        d
        for d in dirs
        if any(
            Path(e.path).parent == Path(d) and Path(e.path).name.lower().startswith("images.")
            for e in entries
        )
    ]
    if len(model_dirs) > 1:
        raise MissionError(f"mission {root} holds several COLMAP models ({', '.join(model_dirs)}): keep one.")
    return root / model_dirs[0] if model_dirs else None


def capture_time(
    photos: dict[str, PhotoMeta], entries: Sequence[FileEntry], scan: LasScan, root: Path,
    given: datetime | None = None,
) -> tuple[datetime, str]:  # fmt: skip
    """(UTC capture time, where it came from): ``given`` (``--captured-at``) when given; else the
    earliest photo time; else the raw folder's DJI_YYYYMMDDHHMM; else the LAS creation date and GPS
    time."""
    if given is not None:
        return given.astimezone(UTC), "given (--captured-at)"
    times = [m.capture_time for m in photos.values() if m.capture_time is not None]
    if times:
        return min(times), "photos"
    for e in entries:
        m = RAW_FOLDER.match(Path(e.path).parts[0])
        if m:
            return datetime.strptime(m.group(1), "%Y%m%d%H%M").replace(tzinfo=UTC), "raw folder name"
    day = date.fromisoformat(scan.creation_date) if scan.creation_date else None
    if day is None:
        raise MissionError(
            f"mission {root}: no photo time, no DJI raw folder name (DJI_YYYYMMDDHHMM_...) and no creation date "
            f"in the header of {root / scan.path}: the capture time is unknown; give it with "
            "--captured-at (ISO 8601, e.g. 2024-11-27T16:31:00Z)."
        )
    t = datetime(day.year, day.month, day.day, tzinfo=UTC)
    if scan.gps_time_range is not None:
        t += timedelta(seconds=(scan.gps_time_range[0] % 86400.0) - GPS_UTC_OFFSET_S)
    return t, "las header"


def mission_name(entries: Sequence[FileEntry], root: Path) -> str:
    """The name a mission is known by: its raw DJI folder's, else its one file's stem (a mission of a
    bare LAS/LAZ), else its folder's."""
    if len(entries) == 1 and "/" not in entries[0].path:
        return Path(entries[0].path).stem
    return next(
        (Path(e.path).parts[0] for e in entries if RAW_FOLDER.match(Path(e.path).parts[0])), root.name
    )
