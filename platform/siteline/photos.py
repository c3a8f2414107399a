"""DJI photo metadata (DESIGN.md §9.2), read and written: the ``drone-dji`` XMP packet, with EXIF as
fallback; a shared primitive (ingest, registration and the synthetic site use it).

The XMP packet is found in the raw bytes; values may be attributes or elements, signed strings
("+32.50"); both the current namespace ``http://www.dji.com/drone-dji/1.0/`` and the old thermal one
``http://www.dji.com`` are read, and so is the ``GpsLongtitude`` misspelling.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from siteline.errors import PhotoError

# compared without a trailing slash: legacy cameras write both "http://www.dji.com" and ".../"
DJI_NAMESPACES = ("http://www.dji.com/drone-dji/1.0", "http://www.dji.com")
_XMP_START = b"<x:xmpmeta"
_XMP_END = b"</x:xmpmeta>"
# scan at most this much of a file for the XMP packet (DJI writes it in the first APP1 segments)
MAX_SCAN_BYTES = 4 * 2**20

_ALIASES = {
    "latitude_deg": ("GpsLatitude", "Latitude"),
    "longitude_deg": ("GpsLongitude", "GpsLongtitude", "Longitude"),
    "absolute_altitude_m": ("AbsoluteAltitude",),
    "relative_altitude_m": ("RelativeAltitude",),
    "gimbal_roll_deg": ("GimbalRollDegree",),
    "gimbal_yaw_deg": ("GimbalYawDegree",),
    "gimbal_pitch_deg": ("GimbalPitchDegree",),
    "flight_roll_deg": ("FlightRollDegree",),
    "flight_yaw_deg": ("FlightYawDegree",),
    "flight_pitch_deg": ("FlightPitchDegree",),
    "rtk_flag": ("RtkFlag",),
    "rtk_std_lon_m": ("RtkStdLon",),
    "rtk_std_lat_m": ("RtkStdLat",),
    "rtk_std_hgt_m": ("RtkStdHgt",),
    "calibrated_focal_length_px": ("CalibratedFocalLength",),
    "calibrated_optical_center_x_px": ("CalibratedOpticalCenterX",),
    "calibrated_optical_center_y_px": ("CalibratedOpticalCenterY",),
}


@dataclass(frozen=True)
class PhotoMeta:
    """What a DJI photo says about itself. Angles in degrees (DJI NED conventions), altitudes in
    metres (absolute: ellipsoidal with RTK), standard deviations in metres, intrinsics in pixels.
    ``source`` is ``xmp`` or ``exif``."""

    file: str
    source: str
    latitude_deg: float | None = None
    longitude_deg: float | None = None
    absolute_altitude_m: float | None = None
    relative_altitude_m: float | None = None
    gimbal_roll_deg: float | None = None
    gimbal_yaw_deg: float | None = None
    gimbal_pitch_deg: float | None = None
    flight_roll_deg: float | None = None
    flight_yaw_deg: float | None = None
    flight_pitch_deg: float | None = None
    rtk_flag: int | None = None
    rtk_std_lon_m: float | None = None
    rtk_std_lat_m: float | None = None
    rtk_std_hgt_m: float | None = None
    calibrated_focal_length_px: float | None = None
    calibrated_optical_center_x_px: float | None = None
    calibrated_optical_center_y_px: float | None = None
    dewarp: tuple[float, ...] | None = None
    capture_time: datetime | None = None
    width: int | None = None
    height: int | None = None
    make: str | None = None
    model: str | None = None

    @property
    def has_position(self) -> bool:
        return (
            self.latitude_deg is not None
            and self.longitude_deg is not None
            and self.absolute_altitude_m is not None
        )

    @property
    def has_orientation(self) -> bool:
        return self.gimbal_yaw_deg is not None and self.gimbal_pitch_deg is not None

    @property
    def rtk_fixed(self) -> bool:
        return self.rtk_flag == 50

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["capture_time"] = self.capture_time.isoformat() if self.capture_time else None
        d["dewarp"] = list(self.dewarp) if self.dewarp else None
        return d


def _number(text: str, what: str, path: Path) -> float:
    try:
        value = float(text.strip())
    except ValueError as exc:
        raise PhotoError(f"photo {path}: {what}={text!r} is not a number.") from exc
    if not math.isfinite(value):
        raise PhotoError(f"photo {path}: {what}={text!r} is not finite.")
    return value


def find_xmp(data: bytes) -> bytes | None:
    """The raw ``<x:xmpmeta>...</x:xmpmeta>`` packet in a file's bytes, or None."""
    start = data.find(_XMP_START)
    if start < 0:
        return None
    end = data.find(_XMP_END, start)
    if end < 0:
        return None
    return data[start : end + len(_XMP_END)]


def _dji_fields(xmp: bytes) -> dict[str, str]:
    """Every DJI-namespace value in the packet, attributes and elements alike, by local name."""
    try:
        root = ET.fromstring(xmp)
    except ET.ParseError:
        # stray bytes or an undeclared prefix (some legacy firmware): a tolerant scan of the
        # drone-dji: and DJI: attributes and elements
        tolerant: dict[str, str] = {}
        for m in re.finditer(rb'(?:drone-dji|DJI):(\w+)="([^"]*)"', xmp):
            tolerant[m.group(1).decode()] = m.group(2).decode(errors="replace")
        for m in re.finditer(rb"<(drone-dji|DJI):(\w+)>([^<]*)</\1:\2>", xmp):
            if m.group(3).strip():
                tolerant[m.group(2).decode()] = m.group(3).decode(errors="replace").strip()
        return tolerant
    out: dict[str, str] = {}
    for el in root.iter():
        for key, value in el.attrib.items():
            if key.startswith("{"):
                ns, local = key[1:].split("}", 1)
                if ns.rstrip("/") in DJI_NAMESPACES:
                    out[local] = value
        if el.tag.startswith("{"):
            ns, local = el.tag[1:].split("}", 1)
            if ns.rstrip("/") in DJI_NAMESPACES and el.text and el.text.strip():
                out[local] = el.text.strip()
    return out


def _exif(path: Path) -> tuple[dict[str, Any], int | None, int | None]:
    from PIL import ExifTags, Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            exif = im.getexif()
            size = im.size
    except (UnidentifiedImageError, OSError) as exc:
        raise PhotoError(f"photo {path} is not a readable image: {exc}") from exc
    fields: dict[str, Any] = {str(ExifTags.TAGS.get(k, k)): v for k, v in exif.items()}
    fields.update({str(ExifTags.TAGS.get(k, k)): v for k, v in exif.get_ifd(ExifTags.IFD.Exif).items()})
    gps = exif.get_ifd(ExifTags.IFD.GPSInfo)
    fields["_gps"] = {ExifTags.GPSTAGS.get(k, k): v for k, v in gps.items()}
    return fields, size[0], size[1]


def _dms(value: Any, ref: str, positive: str) -> float:
    d, m, s = (float(v) for v in value)
    deg = d + m / 60.0 + s / 3600.0
    return deg if ref.upper() == positive else -deg


def _exif_time(text: str | None) -> datetime | None:
    if not text:
        return None
    try:
        # DJI writes local time without zone; siteline treats it as UTC unless XMP says otherwise
        return datetime.strptime(str(text).strip(), "%Y:%m:%d %H:%M:%S").replace(tzinfo=UTC)
    except ValueError:
        return None


def read_photo_meta(path: Path) -> PhotoMeta:
    """Parse a photo's DJI XMP (EXIF GPS and time as fallback); :class:`PhotoError` when the file
    has no usable position."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(MAX_SCAN_BYTES)
    except OSError as exc:
        raise PhotoError(f"photo {path} cannot be read: {exc}") from exc
    exif, width, height = _exif(path)
    values: dict[str, Any] = {
        "file": str(path),
        "width": width,
        "height": height,
        "make": exif.get("Make"),
        "model": exif.get("Model"),
        "capture_time": _exif_time(exif.get("DateTimeOriginal") or exif.get("DateTime")),
    }
    xmp = find_xmp(head)
    fields = _dji_fields(xmp) if xmp else {}
    for name, aliases in _ALIASES.items():
        for alias in aliases:
            if alias in fields and fields[alias].strip() != "":
                v = _number(fields[alias], alias, path)
                values[name] = int(v) if name == "rtk_flag" else v
                break
    if "DewarpData" in fields and ";" in fields["DewarpData"]:
        parts = fields["DewarpData"].split(";", 1)[1].split(",")
        values["dewarp"] = tuple(_number(p, "DewarpData", path) for p in parts)
    source = "xmp" if "latitude_deg" in values else "exif"
    if source == "exif":
        gps = exif.get("_gps", {})
        if {"GPSLatitude", "GPSLatitudeRef", "GPSLongitude", "GPSLongitudeRef"} <= gps.keys():
            values["latitude_deg"] = _dms(gps["GPSLatitude"], gps["GPSLatitudeRef"], "N")
            values["longitude_deg"] = _dms(gps["GPSLongitude"], gps["GPSLongitudeRef"], "E")
            if "GPSAltitude" in gps:
                alt = float(gps["GPSAltitude"])
                values["absolute_altitude_m"] = -alt if gps.get("GPSAltitudeRef") in (1, b"\x01") else alt
    meta = PhotoMeta(source=source, **{k: v for k, v in values.items() if k != "source"})
    if not meta.has_position or meta.latitude_deg is None or meta.longitude_deg is None:
        raise PhotoError(
            f"photo {path} has no usable position: no DJI XMP GpsLatitude/GpsLongitude/"
            "AbsoluteAltitude and no EXIF GPS."
        )
    if not (-90 <= meta.latitude_deg <= 90 and -180 <= meta.longitude_deg <= 180):
        raise PhotoError(
            f"photo {path}: position ({meta.latitude_deg}, {meta.longitude_deg}) is outside the globe."
        )
    return meta


def signed(value: float, decimals: int) -> str:
    """DJI's signed-string form of a number: ``+32.50``, ``-10.500``."""
    return f"{value:+.{decimals}f}"


def dji_xmp(fields: dict[str, str]) -> bytes:
    """An XMP packet with the given ``drone-dji`` attributes (values already formatted)."""
    attrs = "\n".join(f'   drone-dji:{k}="{v}"' for k, v in fields.items())
    return (
        '<x:xmpmeta xmlns:x="adobe:ns:meta/">\n <rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">\n'
        '  <rdf:Description rdf:about="DJI Meta Data"\n    xmlns:tiff="http://ns.adobe.com/tiff/1.0/"\n'
        '    xmlns:drone-dji="http://www.dji.com/drone-dji/1.0/"\n   tiff:Make="DJI"\n   tiff:Model="M350 RTK"\n'
        f"{attrs}>\n  </rdf:Description>\n </rdf:RDF>\n</x:xmpmeta>"
    ).encode()
