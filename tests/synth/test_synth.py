"""The synthetic site: determinism, LAS and photo encoding, COLMAP model, ground truth."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pycolmap
import pyproj
import pytest
from scipy.spatial.transform import Rotation

from siteline.camera.photos import read_photo_meta
from siteline.camera.pinhole import Camera
from siteline.register.xmp import camera_from_photo
from siteline.synth import LAS_RELPATH, SynthParams, write_site
from siteline.synth import model as m

CFG = SynthParams(epochs=3, density_pts_m2=3.0, seed=3)


@pytest.fixture(scope="module")
def site_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("synth")
    write_site(out, CFG)
    return out


def _epochs(site_dir: Path) -> list[dict]:
    return json.loads((site_dir / "truth" / "site.json").read_text())["epochs"]


def _digest(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def test_same_seed_same_bytes(tmp_path) -> None:
    cfg = SynthParams(epochs=2, density_pts_m2=1.0, seed=11)
    write_site(tmp_path / "a", cfg)
    write_site(tmp_path / "b", cfg)
    a, b = _digest(tmp_path / "a"), _digest(tmp_path / "b")
    assert a == b and any(k.endswith(".las") for k in a) and any(k.endswith(".JPG") for k in a)
    write_site(tmp_path / "c", SynthParams(epochs=2, density_pts_m2=1.0, seed=12))
    las = [k for k in a if k.endswith(".las")][0]
    assert _digest(tmp_path / "c")[las] != a[las]


def test_mission_layout_and_las_header(site_dir) -> None:
    for ep in _epochs(site_dir):
        mission = site_dir / ep["mission_dir"]
        las = laspy.read(mission / LAS_RELPATH)
        h = las.header
        assert (h.version.major, h.version.minor) == (1, 2) and h.point_format.id == 3
        assert np.allclose(h.scales, 0.001)
        assert np.abs(las.x - h.offsets[0]).max() < 1000 and np.abs(las.y - h.offsets[1]).max() < 1000
        assert h.parse_crs().to_epsg() == 32618
        assert len(las.points) == ep["points"] > 0
        raw = [p for p in mission.iterdir() if p.name.startswith("DJI_") and p.is_dir()]
        assert len(raw) == 1
        exts = {p.suffix for p in raw[0].iterdir()}
        assert {".LDR", ".IMU", ".RTK", ".CLC", ".CLI", ".JPG"} <= exts
        assert ep["points"] < 300_000


def test_photo_xmp_poses_match_truth(site_dir) -> None:
    crs = pyproj.CRS.from_user_input(CFG.crs)
    for ep in _epochs(site_dir):
        truth = json.loads((site_dir / "truth" / ep["name"] / "cameras.json").read_text())
        raw = next(
            p for p in (site_dir / ep["mission_dir"]).iterdir() if p.is_dir() and p.name.startswith("DJI_")
        )
        assert len(truth) == len(list(raw.glob("*.JPG"))) == ep["photos"]
        for t in truth:
            meta = read_photo_meta(raw / t["name"])
            assert meta.source == "xmp" and meta.rtk_flag == 50
            assert abs(meta.gimbal_yaw_deg - t["gimbal_yaw_deg"]) < 1e-6
            assert abs(meta.gimbal_pitch_deg - t["gimbal_pitch_deg"]) < 1e-6
            cam = camera_from_photo(meta, crs, CFG.origin)
            true_cam = Camera.from_dict(t["camera"])
            assert np.abs(cam.center - true_cam.center).max() < 1e-3
            angle = np.degrees(Rotation.from_matrix(cam.R.T @ true_cam.R).magnitude())
            assert angle < 1e-6
            assert (cam.width, cam.height, cam.fx) == (
                true_cam.width,
                true_cam.height,
                pytest.approx(true_cam.fx),
            )
            assert meta.capture_time is not None


def test_colmap_model_recovers_true_poses(site_dir) -> None:
    for ep in _epochs(site_dir):
        rec = pycolmap.Reconstruction(site_dir / ep["mission_dir"] / "colmap" / "sparse" / "0")
        truth = {
            t["name"]: t for t in json.loads((site_dir / "truth" / ep["name"] / "cameras.json").read_text())
        }
        assert rec.num_reg_images() == len(truth)
        sim = json.loads((site_dir / "truth" / ep["name"] / "epoch.json").read_text())[
            "colmap_model_from_site"
        ]
        s, R, t = sim["scale"], np.asarray(sim["rotation"]), np.asarray(sim["translation"])
        for img in rec.images.values():
            c_model = img.projection_center()
            c_site = R.T @ (c_model - t) / s
            assert np.abs(c_site - np.asarray(truth[img.name]["center_m"])).max() < 1e-6
        # the model frame is not the site frame
        any_img = next(iter(rec.images.values()))
        assert np.abs(any_img.projection_center() - np.asarray(truth[any_img.name]["center_m"])).max() > 1.0


def _truth(site_dir: Path, name: str, key: str) -> np.ndarray:
    return np.load(site_dir / "truth" / name / f"{key}.npy")


def test_ground_truth_agrees_with_clouds(site_dir) -> None:
    eps = _epochs(site_dir)
    for i, ep in enumerate(eps):
        las = laspy.read(site_dir / ep["mission_dir"] / LAS_RELPATH)
        oid = _truth(site_dir, ep["name"], "object_id")
        since = _truth(site_dir, ep["name"], "changed_since_previous")
        until = _truth(site_dir, ep["name"], "changed_until_next")
        assert len(oid) == len(since) == len(until) == len(las.points)
        assert np.array_equal(_truth(site_dir, ep["name"], "las_class"), np.asarray(las.classification))
        if i == 0:
            assert not since.any()
        if i == len(eps) - 1:
            assert not until.any()
        assert not since[oid == 1].any()  # open terrain never changes
        assert not since[oid == 700].any()  # nor does the fence
    # the pit deepens from 2 m to 4 m between epochs 0 and 1: every pit point changed both ways
    assert _truth(site_dir, eps[1]["name"], "changed_since_previous")[
        _truth(site_dir, eps[1]["name"], "object_id") == 2
    ].all()
    assert _truth(site_dir, eps[0]["name"], "changed_until_next")[
        _truth(site_dir, eps[0]["name"], "object_id") == 2
    ].all()


def test_dynamic_objects_move_between_epochs(site_dir) -> None:
    eps = _epochs(site_dir)
    centroids = []
    for ep in eps[:2]:
        las = laspy.read(site_dir / ep["mission_dir"] / LAS_RELPATH)
        oid = _truth(site_dir, ep["name"], "object_id")
        xyz = np.c_[las.x, las.y, las.z]
        centroids.append({o: xyz[oid == o].mean(axis=0) for o in (300, 301, 302) if (oid == o).any()})
    moved = [np.linalg.norm(centroids[0][o] - centroids[1][o]) for o in centroids[0] if o in centroids[1]]
    assert moved and min(moved) > 1.0


def test_no_points_under_slabs(site_dir) -> None:
    ep = _epochs(site_dir)[2]  # two floors
    las = laspy.read(site_dir / ep["mission_dir"] / LAS_RELPATH)
    local = np.c_[las.x, las.y, las.z] - np.asarray(CFG.origin)
    oid = _truth(site_dir, ep["name"], "object_id")
    bx0, bx1, by0, by1 = m.BUILDING_M
    inner = (
        (local[:, 0] > bx0 + 1) & (local[:, 0] < bx1 - 1) & (local[:, 1] > by0 + 1) & (local[:, 1] < by1 - 1)
    )
    assert (inner & (oid == 100)).sum() > 100
    assert (inner & (oid == 1)).sum() == 0  # the terrain under the foundation slab is never seen


def test_nadir_only_flight_sees_nothing_under_the_top_slab() -> None:
    from siteline.synth.lidar import LidarSpec, sample_epoch

    site = m.SiteModel(seed=0, n_epochs=4)
    pts = np.concatenate(
        [c.xyz for c in sample_epoch(site, 3, LidarSpec(density_pts_m2=2.0, oblique_tilts_deg=()))]
    )
    bx0, bx1, by0, by1 = m.BUILDING_M
    inner = (pts[:, 0] > bx0 + 2) & (pts[:, 0] < bx1 - 2) & (pts[:, 1] > by0 + 2) & (pts[:, 1] < by1 - 2)
    inner &= pts[:, 2] < 30.0  # below the crane jib
    top = pts[inner, 2].max()
    assert top > 10.0
    assert (pts[inner, 2] < top - 0.5).sum() == 0


def test_origin_moves_the_whole_site(tmp_path) -> None:
    a = SynthParams(epochs=1, density_pts_m2=1.0, seed=5, photos=False, colmap=False)
    b = SynthParams(
        epochs=1,
        density_pts_m2=1.0,
        seed=5,
        photos=False,
        colmap=False,
        origin=(500_000.0, 4_000_000.0, 300.0),
    )
    write_site(tmp_path / "a", a)
    write_site(tmp_path / "b", b)
    la = laspy.read(next((tmp_path / "a").rglob("*.las")))
    lb = laspy.read(next((tmp_path / "b").rglob("*.las")))
    da = np.c_[la.x, la.y, la.z] - np.asarray(a.origin)
    db = np.c_[lb.x, lb.y, lb.z] - np.asarray(b.origin)
    assert np.abs(da - db).max() <= 0.0011  # both quantised to the 1 mm LAS scale
    assert not list((tmp_path / "a").rglob("*.JPG"))


@pytest.mark.slow
def test_memory_flat_when_density_quadruples(tmp_path) -> None:
    code = (
        "import resource, sys\n"
        "from siteline.synth import SynthParams, write_site\n"
        "write_site(sys.argv[1], SynthParams(epochs=1, density_pts_m2=float(sys.argv[2]), photos=False, colmap=False))\n"
        "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    )
    peaks = {}
    for d in (40.0, 160.0):
        out = subprocess.run(
            [sys.executable, "-c", code, str(tmp_path / f"d{d:g}"), str(d)],
            capture_output=True,
            text=True,
            check=True,
        )
        peaks[d] = int(out.stdout.split()[-1])
    assert peaks[160.0] < 1.3 * peaks[40.0], peaks
