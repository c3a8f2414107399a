"""A mission that cannot tell when it was captured (a LiDAR-only LAS without a creation date): refused
naming the LAS file and the way past it, then ingested with ``--captured-at``, recorded as given."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from sitehelpers import run_cli

from siteline.catalog.context import StageContext
from siteline.errors import MissionError
from siteline.ingest.options import IngestOptions
from siteline.ingest.stage import ingest_mission
from siteline.pointpass import write_las

# LAS 1.x header: file creation day of year at byte 90, year at byte 92 (both uint16)
CREATION_OFFSET = 90


def _undated_mission(root):
    rng = np.random.default_rng(3)
    xyz = np.c_[rng.uniform(-20, 20, (3000, 2)), rng.normal(0, 0.02, 3000)] + [445_000.0, 5_030_000.0, 80.0]
    las = root / "lidars" / "terra_las" / "cloud_merged.las"
    write_las(las, xyz, crs="EPSG:32618", classification=np.full(3000, 2, np.uint8))
    data = bytearray(las.read_bytes())
    data[CREATION_OFFSET : CREATION_OFFSET + 4] = struct.pack("<HH", 0, 0)  # as laspy's simple.las: no date
    las.write_bytes(bytes(data))
    return root, las


def test_undated_lidar_only_mission_is_refused_naming_the_las(cat, site_settings, tmp_path) -> None:
    mission, las = _undated_mission(tmp_path / "undated")
    with pytest.raises(MissionError) as err:
        ingest_mission(StageContext(cat, site_settings), mission, "demo")
    assert str(las) in str(err.value) and "--captured-at" in str(err.value)
    with pytest.raises(MissionError, match="no time zone"):
        IngestOptions(captured_at=__import__("datetime").datetime(2024, 6, 1, 10))


def test_captured_at_ingests_it_and_scene_show_says_so(capsys, home, tmp_path) -> None:
    from sitehelpers import SYNTH

    mission, _ = _undated_mission(tmp_path / "undated")
    assert run_cli(capsys, "init")[0] == 0
    code, _, err = run_cli(
        capsys, "site", "create", "demo", "--crs", SYNTH.crs, "--origin", *(str(v) for v in SYNTH.origin)
    )
    assert code == 0, err
    code, _, err = run_cli(capsys, "ingest", str(mission), "--site", "demo", "--captured-at", "yesterday")
    assert code == 2 and "--captured-at 'yesterday' is not an ISO 8601 time" in err
    code, out, err = run_cli(
        capsys,
        "ingest",
        str(mission),
        "--site",
        "demo",
        "--captured-at",
        "2024-06-01T10:30:00+02:00",
        "--json",
    )
    assert code == 0, err
    scene = json.loads(out)["scene_id"]
    code, out, _ = run_cli(capsys, "scene", "show", str(scene), "--json")
    shown = json.loads(out)
    assert shown["capture_time"] == "2024-06-01T08:30:00+00:00"
    assert shown["capture_time_source"] == "given (--captured-at)"
