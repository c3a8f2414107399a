"""Reading a mission folder's contents: which point cloud, which photos, which COLMAP model, and when
it was captured (DESIGN.md §9)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from datetime import UTC, date, datetime, timedelta
from pathlib import Path

from siteline.camera.photos import PhotoMeta, read_photo_meta
from siteline.errors import MissionError, PhotoError
from siteline.records.mission import FileEntry
from siteline.records.scan import LasScan

PREFERRED_LAS = ("lidars/terra_las/cloud_merged.las", "lidars/terra_las/cloud_merged.laz")
RAW_FOLDER = re.compile(r"^DJI_(\d{12})_\d{3}_")
GPS_EPOCH = datetime(1980, 1, 6, tzinfo=UTC)
# GPS time runs ahead of UTC by the leap seconds since 1980: (UTC day from which it applies, seconds)
LEAP_SECONDS = (
    (date(1981, 7, 1), 1), (date(1982, 7, 1), 2), (date(1983, 7, 1), 3), (date(1985, 7, 1), 4),
    (date(1988, 1, 1), 5), (date(1990, 1, 1), 6), (date(1991, 1, 1), 7), (date(1992, 7, 1), 8),
    (date(1993, 7, 1), 9), (date(1994, 7, 1), 10), (date(1996, 1, 1), 11), (date(1997, 7, 1), 12),
    (date(1999, 1, 1), 13), (date(2006, 1, 1), 14), (date(2009, 1, 1), 15), (date(2012, 7, 1), 16),
    (date(2015, 7, 1), 17), (date(2017, 1, 1), 18),
)  # fmt: skip
# adjusted standard GPS time (LAS global encoding bit 0) is GPS seconds since the epoch less 1e9
ADJUSTED_GPS_OFFSET_S = 1e9


def gps_to_utc(gps_seconds: float) -> datetime:
    """UTC of seconds since the GPS epoch (1980-01-06), less the leap seconds then in force."""
    t = GPS_EPOCH + timedelta(seconds=gps_seconds)
    leap = max((n for day, n in LEAP_SECONDS if t.date() >= day), default=0)
    return t - timedelta(seconds=leap)


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
    earliest photo time; else the raw folder's DJI_YYYYMMDDHHMM; else the LAS's earliest GPS time
    when it is adjusted standard GPS time (absolute). A LAS whose GPS times are seconds of an unknown
    week, or that has none, cannot tell: its header's creation day is when the file was written
    (an export of a 2010 scan made in 2025), so the mission is refused, naming what the file holds."""
    if given is not None:
        return given.astimezone(UTC), "given (--captured-at)"
    times = [m.capture_time for m in photos.values() if m.capture_time is not None]
    if times:
        return min(times), "photos"
    for e in entries:
        m = RAW_FOLDER.match(Path(e.path).parts[0])
        if m:
            return datetime.strptime(m.group(1), "%Y%m%d%H%M").replace(tzinfo=UTC), "raw folder name"
    if scan.gps_time_range is not None and scan.gps_time_standard:
        return gps_to_utc(scan.gps_time_range[0] + ADJUSTED_GPS_OFFSET_S), "las gps time (adjusted standard)"
    holds = (
        "GPS times in seconds of an unnamed GPS week" if scan.gps_time_range is not None else "no GPS time"
    )
    made = (
        f"; its header's creation day {scan.creation_date} is when the file was written"
        if scan.creation_date
        else ""
    )
    raise MissionError(
        f"mission {root}: no photo time, no DJI raw folder name (DJI_YYYYMMDDHHMM_...) and {root / scan.path} "
        f"holds {holds}{made}: the capture time is unknown and scenes are ordered by it; give it with "
        "--captured-at (ISO 8601, e.g. 2024-11-27T16:31:00Z)."
    )


def mission_name(entries: Sequence[FileEntry], root: Path) -> str:
    """The name a mission is known by: its raw DJI folder's, else its one file's stem (a mission of a
    bare LAS/LAZ), else its folder's."""
    if len(entries) == 1 and "/" not in entries[0].path:
        return Path(entries[0].path).stem
    return next(
        (Path(e.path).parts[0] for e in entries if RAW_FOLDER.match(Path(e.path).parts[0])), root.name
    )
