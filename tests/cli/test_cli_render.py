"""`siteline render` and `siteline views generate` on small LAS files."""

from __future__ import annotations

import json

import numpy as np
from PIL import Image
from sitehelpers import run_cli

from siteline.camera.pinhole import Camera
from siteline.pointpass import write_las
from siteline.site.fence import fence_geojson

ORIGIN = (445000.0, 5030000.0, 80.0)


run = run_cli


def _cloud(tmp_path):
    rng = np.random.default_rng(0)
    ground = np.c_[rng.uniform(-60, 60, (40000, 2)), rng.normal(0, 0.02, 40000)]
    box = np.c_[rng.uniform(-5, 5, (4000, 2)), rng.uniform(0, 10, 4000)]
    xyz = np.concatenate([ground, box]) + np.asarray(ORIGIN)
    cls = np.r_[np.full(len(ground), 2), np.full(len(box), 6)].astype(np.uint8)
    rgb = rng.integers(0, 256, (len(xyz), 3), dtype=np.uint8)
    path = tmp_path / "cloud.laz"
    write_las(path, xyz, crs="EPSG:32618", rgb=rgb, classification=cls)
    return path


def test_render_writes_outputs(tmp_path, capsys) -> None:
    las = _cloud(tmp_path)
    cam = Camera.look_at((0, -40, 30), (0, 0, 0), 640, 480, fx=500.0)
    (tmp_path / "cam.json").write_text(json.dumps(cam.to_dict()))
    out = tmp_path / "r"
    code, stdout, err = run(
        capsys,
        "render",
        str(las),
        "--camera",
        str(tmp_path / "cam.json"),
        "--scale",
        "0.25",
        "--out",
        str(out),
        "--origin",
        *map(str, ORIGIN),
        "--json",
    )
    assert code == 0, err
    rec = json.loads(stdout)
    assert rec["points_read"] == 44000 and rec["width"] == 160 and 0 < rec["coverage"] <= 1
    assert Image.open(out / "rgb.png").size == (160, 120)
    hit = np.asarray(Image.open(out / "hit.png")) > 0
    depth = np.load(out / "depth.npy")
    assert np.isfinite(depth[hit]).all() and np.isnan(depth[~hit]).all()
    assert json.loads((out / "stats.json").read_text())["coverage"] == rec["coverage"]


def test_render_without_origin_on_georeferenced_cloud_is_refused(tmp_path, capsys) -> None:
    las = _cloud(tmp_path)
    cam = Camera.look_at((0, -40, 30), (0, 0, 0), 64, 48, fx=50.0)
    (tmp_path / "cam.json").write_text(json.dumps(cam.to_dict()))
    code, _, err = run(
        capsys, "render", str(las), "--camera", str(tmp_path / "cam.json"), "--out", str(tmp_path / "r")
    )
    assert code == 2 and "origin" in err and "cloud.laz" in err
    assert "(0.0, 0.0, 0.0)" in err and "np.float64" not in err  # the origin as plain numbers


def test_render_bad_inputs_are_named(tmp_path, capsys) -> None:
    (tmp_path / "cam.json").write_text("{not json")
    bad = tmp_path / "bad.las"
    bad.write_bytes(b"LASF" + b"\0" * 50)
    code, _, err = run(
        capsys, "render", str(bad), "--camera", str(tmp_path / "cam.json"), "--out", str(tmp_path / "r")
    )
    assert code == 2 and "cam.json" in err
    cam = Camera.look_at((0, -40, 30), (0, 0, 0), 64, 48, fx=50.0)
    (tmp_path / "cam.json").write_text(json.dumps(cam.to_dict()))
    code, _, err = run(
        capsys, "render", str(bad), "--camera", str(tmp_path / "cam.json"), "--out", str(tmp_path / "r")
    )
    assert code == 2 and "bad.las" in err
    code, _, err = run(
        capsys,
        "render",
        str(bad),
        "--camera",
        str(tmp_path / "cam.json"),
        "--out",
        str(tmp_path / "r"),
        "--point-size",
        "2",
    )
    assert code == 2 and "point size" in err


def test_views_generate(tmp_path, capsys) -> None:
    las = _cloud(tmp_path)
    cams = [
        dict(Camera.look_at((x, y, 40), (0, 0, 0), 320, 240, fx=260.0).to_dict(), name=f"DJI_{i}.JPG")
        for i, (x, y) in enumerate([(-70, 0), (70, 5), (0, -70)])
    ]
    (tmp_path / "cams.json").write_text(json.dumps(cams))
    fence = [(-50, -50), (50, -50), (50, 50), (-50, 50)]
    (tmp_path / "fence.geojson").write_text(json.dumps(fence_geojson(fence, ORIGIN)))
    out = tmp_path / "views.json"
    code, stdout, err = run(
        capsys,
        "views",
        "generate",
        "--cameras",
        str(tmp_path / "cams.json"),
        "--ground",
        str(las),
        "--fence",
        str(tmp_path / "fence.geojson"),
        "--origin",
        *map(str, ORIGIN),
        "--n",
        "20",
        "--seed",
        "0",
        "--scale",
        "0.25",
        "--min-coverage",
        "0.3",
        "--out",
        str(out),
        "--json",
    )
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["candidates"] == 96
    doc = json.loads(out.read_text())
    assert len(doc["views"]) == summary["kept"] > 0
    assert {v["parent"] for v in doc["views"]} <= {"DJI_0.JPG", "DJI_1.JPG", "DJI_2.JPG"}
