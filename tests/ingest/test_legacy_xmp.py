"""Legacy DJI XMP (``http://www.dji.com``, prefix ``DJI:``) is read before EXIF."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from legacy_dji import legacy_photo  # tests/legacy_dji.py, beside sitehelpers

from siteline.camera.photos import read_photo_meta


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


@pytest.mark.parametrize(
    ("kw", "how"),
    [
        # XT S firmware V190918: xmlns:DJI twice on one rdf:Description (not well-formed XML)
        ({"form": "attributes", "twice": True}, "xmp (repaired: repeated xmlns:DJI)"),
        ({"form": "elements", "twice": True}, "xmp (repaired: repeated xmlns:DJI)"),
        ({"form": "attributes", "quote": "'"}, "xmp"),
        (
            {"form": "attributes", "twice": True, "quote": "'", "root": "xapmeta"},
            "xmp (repaired: repeated xmlns:DJI)",
        ),
    ],
)
def test_real_firmware_packets_are_read_and_each_field_names_its_source(tmp_path, kw, how) -> None:
    path = tmp_path / "DJI_0003_R.JPG"
    path.write_bytes(legacy_photo(**kw))
    meta = read_photo_meta(path)
    assert meta.source == "xmp" and meta.absolute_altitude_m == -29.44  # EXIF says -29.4
    assert meta.sources["absolute_altitude_m"] == how and meta.sources["gimbal_yaw_deg"] == how
    assert meta.sources["width"] == "exif" and meta.sources["make"] == "exif"


def test_a_packet_no_parser_reads_is_scanned_and_says_so(tmp_path) -> None:
    path = tmp_path / "DJI_0004_R.JPG"
    # an unescaped '&' makes the packet unreadable as XML even after repair
    path.write_bytes(legacy_photo("attributes").replace(b'rdf:about=""', b'rdf:about="a&b"'))
    meta = read_photo_meta(path)
    assert meta.absolute_altitude_m == -29.44
    assert meta.sources["absolute_altitude_m"] == "xmp (tolerant scan)"


def test_photo_inspect_reports_the_source_per_field(tmp_path) -> None:
    path = tmp_path / "DJI_0005_R.JPG"
    path.write_bytes(legacy_photo("attributes", twice=True))
    exe = Path(sys.executable).with_name("siteline")
    done = subprocess.run([str(exe), "photo", "inspect", str(path), "--json"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    record = json.loads(done.stdout)
    assert record["absolute_altitude_m"] == -29.44
    assert record["sources"]["absolute_altitude_m"] == "xmp (repaired: repeated xmlns:DJI)"
    wide = {**os.environ, "COLUMNS": "200"}
    text = subprocess.run([str(exe), "photo", "inspect", str(path)], capture_output=True, text=True, env=wide)
    assert text.returncode == 0 and "repeated xmlns:DJI" in text.stdout
