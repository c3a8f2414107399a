"""Seeded generator of legacy DJI photos: XMP in the old thermal/XT namespace ``http://www.dji.com``
with the ``DJI:`` prefix, as elements or attributes, and an EXIF GPS block rounded as those cameras
write it (so a parser that falls back to EXIF is caught: -29.4 m there against -29.44 m in the XMP)."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image

VALUES = {
    "GpsLatitude": "+45.3876432100",
    "GpsLongitude": "-75.6981234500",
    "AbsoluteAltitude": "-29.44",
    "RelativeAltitude": "+62.30",
    "GimbalRollDegree": "+0.00",
    "GimbalYawDegree": "-112.40",
    "GimbalPitchDegree": "-90.00",
    "FlightRollDegree": "+1.20",
    "FlightYawDegree": "-110.90",
    "FlightPitchDegree": "-2.30",
}


def legacy_xmp(
    form: str,
    namespace: str = "http://www.dji.com/",
    declare: bool = True,
    twice: bool = False,
    quote: str = '"',
    root: str = "xmpmeta",
) -> bytes:
    """An XMP packet with VALUES in the legacy ``DJI:`` namespace; ``form``: elements or attributes.
    ``twice`` declares ``xmlns:DJI`` twice on the description, as XT S firmware V190918 does (not
    well-formed XML); ``quote`` is the attribute quote; ``root`` is ``xmpmeta`` or ``xapmeta``."""
    ns = f" xmlns:DJI={quote}{namespace}{quote}" * (2 if twice else 1) if declare else ""
    if form == "elements":
        body = "".join(f"    <DJI:{k}>{v}</DJI:{k}>\n" for k, v in VALUES.items())
        desc = f'  <rdf:Description rdf:about=""{ns}>\n{body}  </rdf:Description>\n'
    elif form == "attributes":
        attrs = "".join(f"\n    DJI:{k}={quote}{v}{quote}" for k, v in VALUES.items())
        desc = f'  <rdf:Description rdf:about=""{ns}{attrs}/>\n'
    else:
        raise ValueError(form)
    return (
        f'<x:{root} xmlns:x="adobe:ns:meta/">\n <rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">\n'
        f"{desc} </rdf:RDF>\n</x:{root}>"
    ).encode()


def legacy_photo(form: str, seed: int = 0, **kw: object) -> bytes:
    """JPEG bytes (64 x 48 noise from ``seed``) with legacy XMP and rounded EXIF GPS."""
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    exif = Image.Exif()
    exif[0x010F] = "DJI"
    exif[0x0110] = "XT2"
    gps = exif.get_ifd(0x8825)
    gps[1], gps[2] = "N", (45.0, 23.0, 15.5)  # 45.3876389: coarser than the XMP
    gps[3], gps[4] = "E", (75.0, 41.0, 53.2)
    gps[3] = "W"
    gps[5], gps[6] = 1, 29.4  # below sea level, one decimal
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="JPEG", exif=exif.tobytes(), xmp=legacy_xmp(form, **kw))
    return buf.getvalue()
