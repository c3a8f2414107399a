"""Legacy DJI XMP (``http://www.dji.com``, prefix ``DJI:``) is read before EXIF."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from siteline.photos import read_photo_meta

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "data"))
from legacy_dji import legacy_photo  # noqa: E402


@pytest.mark.parametrize(
    ("form", "kw"),
    [
        ("elements", {}),
        ("attributes", {}),
        ("elements", {"namespace": "http://www.dji.com"}),
        ("attributes", {"declare": False}),  # firmware that forgets to declare the prefix
        ("elements", {"declare": False}),
    ],
)
def test_legacy_dji_namespace_is_read_before_exif(tmp_path, form, kw) -> None:
    path = tmp_path / "DJI_0001_R.JPG"
    path.write_bytes(legacy_photo(form, **kw))
    meta = read_photo_meta(path)
    assert meta.source == "xmp"
    assert meta.absolute_altitude_m == -29.44  # EXIF says -29.4
    assert meta.latitude_deg == 45.38764321 and meta.longitude_deg == -75.69812345
    assert (meta.gimbal_yaw_deg, meta.gimbal_pitch_deg, meta.flight_pitch_deg) == (-112.4, -90.0, -2.3)


def test_exif_is_the_fallback_without_any_dji_xmp(tmp_path) -> None:
    path = tmp_path / "DJI_0002_R.JPG"
    data = legacy_photo("elements").replace(b"DJI:", b"XYZ:")
    path.write_bytes(data)
    meta = read_photo_meta(path)
    assert meta.source == "exif" and meta.absolute_altitude_m == pytest.approx(-29.4)
