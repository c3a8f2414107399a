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
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from siteline.errors import PhotoError
from siteline.schema import JSON

# compared without a trailing slash: legacy cameras write both "http://www.dji.com" and ".../"
DJI_NAMESPACES = ("http://www.dji.com/drone-dji/1.0", "http://www.dji.com")
# the packet's root element: x:xmpmeta, or x:xapmeta in files written by older XMP toolkits
_XMP_ROOTS = (b"xmpmeta", b"xapmeta")
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
    ``source`` is where the position came from (``xmp`` or ``exif``); ``sources`` names, per field
    read, how: ``exif``, ``xmp``, ``xmp (repaired: ...)`` for a packet mended before parsing, or
    ``xmp (tolerant scan)`` for one no XML parser reads."""

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
    sources: dict[str, str] = field(default_factory=dict)

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

    def to_dict(self) -> dict[str, JSON]:
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
    """The raw ``<x:xmpmeta>...</x:xmpmeta>`` (or ``x:xapmeta``) packet in a file's bytes, or None."""
    for root in _XMP_ROOTS:
        start = data.find(b"<x:" + root)
        if start >= 0:
            end = data.find(b"</x:" + root + b">", start)
            if end >= 0:
                return data[start : end + len(root) + 5]
    return None


_TAG = re.compile(rb"<[A-Za-z][^<>]*>")
_ATTR = re.compile(rb"""([A-Za-z_][\w.:-]*)\s*=\s*("[^"]*"|'[^']*')""")


def repair_xmp(xmp: bytes) -> tuple[bytes, list[str]]:
    """The packet with what firmware gets wrong mended, and what was mended: an attribute (a namespace
    declaration, as XT S firmware V190918 writes ``xmlns:DJI`` twice) repeated in one tag is kept once;
    a ``drone-dji:`` or ``DJI:`` prefix used but never declared is declared on the root."""
    fixes: list[str] = []

    def dedupe(m: re.Match[bytes]) -> bytes:
        tag, seen, keep, at = m.group(0), set(), [], 0
        for a in _ATTR.finditer(tag):
            name = a.group(1)
            if name in seen:  # the later one goes, whitespace before it too
                keep.append(tag[at : a.start()].rstrip())
                at = a.end()
                fixes.append(f"repeated {name.decode(errors='replace')}")
            seen.add(name)
        return b"".join(keep) + tag[at:]

    fixed = _TAG.sub(dedupe, xmp)
    for prefix, ns in (
        (b"drone-dji", b"http://www.dji.com/drone-dji/1.0/"),
        (b"DJI", b"http://www.dji.com/"),
    ):
        if re.search(rb"[<\s]" + prefix + rb":\w", fixed) and b"xmlns:" + prefix + b"=" not in fixed:
            fixed = re.sub(
                rb"<x:(xmpmeta|xapmeta)", rb"<x:\1 xmlns:" + prefix + b'="' + ns + b'"', fixed, count=1
            )
            fixes.append(f"undeclared {prefix.decode()}:")
    return fixed, fixes


def _tolerant_fields(xmp: bytes) -> dict[str, str]:
    """DJI values scanned from a packet no XML parser reads: attributes (either quote, spaces around
    '=') and elements (with or without attributes) of the ``drone-dji:`` and ``DJI:`` prefixes."""
    found: dict[str, str] = {}
    for m in re.finditer(rb"""(?:drone-dji|DJI):(\w+)\s*=\s*(?:"([^"]*)"|'([^']*)')""", xmp):
        found[m.group(1).decode()] = (m.group(2) if m.group(2) is not None else m.group(3)).decode(
            errors="replace"
        )
    for m in re.finditer(rb"<(drone-dji|DJI):(\w+)(?:\s[^>]*)?>([^<]*)</\1:\2>", xmp):
        if m.group(3).strip():
            found[m.group(2).decode()] = m.group(3).decode(errors="replace").strip()
    return found


def _dji_fields(xmp: bytes) -> tuple[dict[str, str], str]:
    """Every DJI-namespace value in the packet, attributes and elements alike, by local name, and how
    it was read: ``xmp``, ``xmp (repaired: ...)`` or ``xmp (tolerant scan)``."""
    fixed, fixes = repair_xmp(xmp)
    try:
        root = ET.fromstring(fixed)
    except ET.ParseError:
        return _tolerant_fields(xmp), "xmp (tolerant scan)"
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
    return out, f"xmp (repaired: {', '.join(sorted(set(fixes)))})" if fixes else "xmp"


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
    sources = {k: "exif" for k, v in values.items() if v is not None and k != "file"}
    xmp = find_xmp(head)
    fields, how = _dji_fields(xmp) if xmp else ({}, "")
    for name, aliases in _ALIASES.items():
        for alias in aliases:
            if alias in fields and fields[alias].strip() != "":
                v = _number(fields[alias], alias, path)
                values[name], sources[name] = (int(v) if name == "rtk_flag" else v), how
                break
    if "DewarpData" in fields and ";" in fields["DewarpData"]:
        parts = fields["DewarpData"].split(";", 1)[1].split(",")
        values["dewarp"], sources["dewarp"] = tuple(_number(p, "DewarpData", path) for p in parts), how
    gps = exif.get("_gps", {})
    if (
        "latitude_deg" not in values
        and {"GPSLatitude", "GPSLatitudeRef", "GPSLongitude", "GPSLongitudeRef"} <= gps.keys()
    ):
        values["latitude_deg"] = _dms(gps["GPSLatitude"], gps["GPSLatitudeRef"], "N")
        values["longitude_deg"] = _dms(gps["GPSLongitude"], gps["GPSLongitudeRef"], "E")
        sources["latitude_deg"] = sources["longitude_deg"] = "exif"
    if "absolute_altitude_m" not in values and "GPSAltitude" in gps:
        alt = float(gps["GPSAltitude"])
        values["absolute_altitude_m"] = -alt if gps.get("GPSAltitudeRef") in (1, b"\x01") else alt
        sources["absolute_altitude_m"] = "exif"
    source = "xmp" if sources.get("latitude_deg", "exif") != "exif" else "exif"
    meta = PhotoMeta(source=source, sources=sources, **values)
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
