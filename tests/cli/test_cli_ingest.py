"""CLI: ingest, scene list/show, mission list, photo inspect (the real DJI photo)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sitehelpers import cli_create_site, run_cli

from siteline.synth import SynthParams, write_site

REAL_PHOTO = Path(__file__).resolve().parents[1] / "data" / "DJI_H20T.jpg"


run = run_cli


def test_photo_inspect_real_dji_photo(capsys) -> None:
    code, out, err = run(capsys, "photo", "inspect", str(REAL_PHOTO), "--json")
    assert code == 0, err
    meta = json.loads(out)
    assert meta["source"] == "xmp"
    assert meta["latitude_deg"] == 40.5637811 and meta["longitude_deg"] == -79.7649628
    assert meta["absolute_altitude_m"] == 221.404
    assert meta["gimbal_yaw_deg"] == 32.5 and meta["gimbal_pitch_deg"] == -10.5
    assert meta["model"] == "ZH20T" and meta["capture_time"].startswith("2021-05-28")
    code, out, _ = run(capsys, "photo", "inspect", str(REAL_PHOTO))
    assert code == 0 and "40.5637811" in out


def test_photo_inspect_without_metadata(capsys, tmp_path) -> None:
    import numpy as np
    from PIL import Image

    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(tmp_path / "plain.jpg")
    code, _, err = run(capsys, "photo", "inspect", str(tmp_path / "plain.jpg"))
    assert code == 2 and "plain.jpg" in err and "no usable position" in err


def test_xmp_variants_old_namespace_and_misspelling(tmp_path) -> None:
    import numpy as np
    from PIL import Image

    from siteline.camera.photos import read_photo_meta

    xmp = (
        b'<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">'
        b'<rdf:Description xmlns:DJI="http://www.dji.com" DJI:GpsLatitude="+45.5" DJI:GpsLongtitude="-75.25" '
        b'DJI:AbsoluteAltitude="+100.5"><DJI:GimbalYawDegree>-12.25</DJI:GimbalYawDegree>'
        b"<DJI:GimbalPitchDegree>-90.0</DJI:GimbalPitchDegree></rdf:Description></rdf:RDF></x:xmpmeta>"
    )
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(tmp_path / "old.jpg", xmp=xmp)
    meta = read_photo_meta(tmp_path / "old.jpg")
    assert (meta.latitude_deg, meta.longitude_deg, meta.absolute_altitude_m) == (45.5, -75.25, 100.5)
    assert (meta.gimbal_yaw_deg, meta.gimbal_pitch_deg) == (-12.25, -90.0)


def test_ingest_cli_scene_and_mission_commands(home, capsys, tmp_path) -> None:
    site = tmp_path / "site"
    write_site(site, SynthParams(epochs=2, density_pts_m2=2.0, seed=4))
    assert run(capsys, "init")[0] == 0
    code, _, err = cli_create_site(capsys, site / "fence.geojson")
    assert code == 0, err
    missions = sorted((site / "missions").iterdir())
    code, out, err = run(capsys, "ingest", str(missions[0]), "--site", "demo", "--json")
    assert code == 0, err
    first = json.loads(out)
    assert first["created"] and first["scene_id"] == 1
    code, out, _ = run(capsys, "ingest", str(missions[0]), "--site", "demo")
    assert code == 0 and "nothing new" in out
    assert run(capsys, "ingest", str(missions[1]), "--site", "demo", "--reference")[0] == 0
    code, out, _ = run(capsys, "scene", "list", "--site", "demo", "--json")
    listing = json.loads(out)
    assert [s["id"] for s in listing["scenes"]] == [1, 2] and listing["pairs"] == [
        {"id": 1, "t1": 1, "t2": 2}
    ]
    code, out, _ = run(capsys, "scene", "show", "1", "--json")
    shown = json.loads(out)
    assert shown["point_count"] == first["scan"]["point_count"] and shown["cameras"] == 23
    assert shown["class_histogram"]["ground"] > 0
    code, out, _ = run(capsys, "mission", "list", "--json")
    assert [m["storage"] for m in json.loads(out)] == ["copy", "reference"]
    code, _, err = run(capsys, "scene", "show", "99")
    assert code == 2 and "no scene with id 99" in err
    code, _, err = run(capsys, "ingest", str(missions[0]), "--site", "nowhere")
    assert code == 2 and "unknown site 'nowhere'" in err


@pytest.mark.slow  # two epochs ingested and a release built (about a minute)
def test_a_release_of_a_scene_without_ground_finds_its_ground_and_says_so(home, capsys, tmp_path) -> None:
    import laspy
    import numpy as np

    from siteline.synth import LAS_RELPATH

    site = tmp_path / "site"
    write_site(site, SynthParams(epochs=2, density_pts_m2=2.0, seed=4))
    missions = sorted((site / "missions").iterdir())
    las_path = missions[1] / LAS_RELPATH
    las = laspy.read(las_path)
    las.classification = np.zeros(len(las.points), np.uint8)  # a raw scanner export: every point class 0
    las.write(las_path)
    assert run_cli(capsys, "init")[0] == 0
    assert cli_create_site(capsys, site / "fence.geojson")[0] == 0
    for m, extra in zip(missions, ([], ["--accept-misalignment"]), strict=True):  # ICP needs ground too
        code, _, err = run_cli(capsys, "ingest", str(m), "--site", "demo", *extra)
        assert code == 0, err
    code, out, err = run_cli(
        capsys, "release", "build", "--site", "demo", "--name", "noground", "--views", "6", "--json"
    )
    assert code == 0, (out, err)
    root = Path(json.loads(out)["root"])
    (pair,) = json.loads((root / "manifest.json").read_text())["lineage"]["pairs"]
    # the later scene's ground comes from its shape; the synthetic site is flat: a plane
    assert pair["ground"]["source"] == "morphology" and pair["ground"]["model"] == "plane"
    assert "ground found from the points' shape" in (root / "README.md").read_text()
