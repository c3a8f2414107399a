"""Missions and files that try to break ingest: headers that lose or move points, special files and
symlink loops in the folder, and upload leftovers that are not mission content. Each is refused with
one line naming the file (or ignored, for the upload marker), and nothing is written."""

from __future__ import annotations

import os
import struct

import numpy as np
import pytest
import sqlalchemy as sa
from sitehelpers import copy_mission

from siteline.catalog.context import StageContext
from siteline.catalog.models import Mission
from siteline.errors import MissionError, PointCloudError
from siteline.ingest.stage import ingest_mission
from siteline.pointpass import write_las

LAS_NAME = "cloud_merged.las"


def _mission(root, n=4000, scale=0.001):
    rng = np.random.default_rng(5)
    xyz = np.c_[rng.uniform(-20, 20, (n, 2)), rng.normal(0, 0.02, n)] + [445_000.0, 5_030_000.0, 80.0]
    las = root / "lidars" / "terra_las" / LAS_NAME
    write_las(las, xyz, crs="EPSG:32618", classification=np.full(n, 2, np.uint8), scale=scale)
    return las


def _patch(las, offset: int, fmt: str, *values) -> None:
    data = bytearray(las.read_bytes())
    data[offset : offset + struct.calcsize(fmt)] = struct.pack(fmt, *values)
    las.write_bytes(bytes(data))


def _nothing(cat) -> None:
    with cat.transaction() as s:
        assert s.execute(sa.select(sa.func.count(Mission.id))).scalar_one() == 0


# LAS 1.2 header: legacy point count (uint32) at 107, scales (3 x float64) at 131
@pytest.mark.parametrize(
    ("patch", "match"),
    [
        ((107, "<I", 2000), r"counts 2,000 points but the file holds 4,000"),
        ((131, "<ddd", 1e-12, 1e-12, 1e-12), r"scale \[1e-12, 1e-12, 1e-12\] is out of range"),
        ((131, "<ddd", -0.001, 0.001, 0.001), r"scale \[-0.001, 0.001, 0.001\] is out of range"),
    ],
)
def test_headers_that_lose_or_move_points_are_refused(cat, site_settings, tmp_path, patch, match) -> None:
    las = _mission(tmp_path / "m")
    _patch(las, *patch)
    with pytest.raises(PointCloudError, match=match) as err:
        ingest_mission(StageContext(cat, site_settings), tmp_path / "m", "demo", opts=None)
    assert str(las) in str(err.value)
    _nothing(cat)


def test_a_fifo_in_the_mission_is_refused_not_waited_on(cat, site_settings, tmp_path) -> None:
    _mission(tmp_path / "m")
    os.mkfifo(tmp_path / "m" / "pipe")
    with pytest.raises(MissionError, match=r"pipe is a FIFO, not a file"):
        ingest_mission(StageContext(cat, site_settings), tmp_path / "m", "demo")
    _nothing(cat)


def test_symlink_loops_are_refused_by_name(cat, site_settings, tmp_path) -> None:
    _mission(tmp_path / "m")
    os.symlink("b.jpg", tmp_path / "m" / "a.jpg")
    os.symlink("a.jpg", tmp_path / "m" / "b.jpg")
    with pytest.raises(MissionError, match=r"a\.jpg is a symlink loop"):
        ingest_mission(StageContext(cat, site_settings), tmp_path / "m", "demo")
    os.remove(tmp_path / "m" / "a.jpg")
    os.remove(tmp_path / "m" / "b.jpg")
    os.symlink("loop", tmp_path / "m" / "loop")  # a directory-like self loop
    with pytest.raises(MissionError, match=r"loop is a symlink loop"):
        ingest_mission(StageContext(cat, site_settings), tmp_path / "m", "demo")
    _nothing(cat)


def test_the_upload_marker_is_not_mission_content(cat, site_settings, synth_site, tmp_path) -> None:
    """The same mission with and without the watcher's marker is one mission (issue 24's re-upload)."""
    plain = copy_mission(synth_site, 0, tmp_path / "a")
    marked = copy_mission(synth_site, 0, tmp_path / "b")
    (marked / ".upload-complete").write_text("")
    first = ingest_mission(StageContext(cat, site_settings), plain, "demo")
    again = ingest_mission(StageContext(cat, site_settings), marked, "demo")
    assert first.created and not again.created and again.manifest_sha256 == first.manifest_sha256
