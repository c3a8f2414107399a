"""Real public point clouds (tests/data/real) from a bare LAS/LAZ to a published release, through the
installed ``siteline`` executable as a user runs it: no photos (cameras planned from the cloud), no
fence (the scene's footprint), ASPRS 1/2 classes, a feet CRS in WKT, a cloud with RGB and one
without (intensity), and infeasible settings refused in seconds."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from realdata import AUTZEN, TOPOGRAPHY, centre_xy, later_epoch

EXE = Path(sys.executable).parent / "siteline"
AUTZEN_DATES = ("2020-05-01T10:00:00Z", "2020-05-31T10:00:00Z")
pytestmark = pytest.mark.e2e


def _run(home: Path, *argv: str, timeout: float = 600) -> subprocess.CompletedProcess:
    env = os.environ | {"SITELINE_HOME": str(home)}
    for name in ("SITELINE_DATABASE_URL", "SITELINE_STORE_URL", "PREFECT_API_URL"):
        env.pop(name, None)
    return subprocess.run([str(EXE), *argv], capture_output=True, text=True, env=env, timeout=timeout)


def _ok(home: Path, *argv: str) -> str:
    r = _run(home, *argv)
    assert r.returncode == 0, f"siteline {' '.join(argv)}: exit {r.returncode}\n{r.stdout}\n{r.stderr}"
    return r.stdout


def _site(
    tmp: Path, name: str, src: Path, crs: str, origin: tuple[float, float, float], change: dict,
    dates: tuple[str, str] | None = None, ingest: tuple[str, ...] = (),
) -> Path:  # fmt: skip
    """A home with a site of ``src`` and a later epoch of it with ``change`` planted, both ingested
    as bare files (no photos, no fence), dated by ``dates`` (--captured-at) when the files cannot
    tell (GPS week seconds)."""
    home = tmp / "home"
    later = later_epoch(src, tmp / f"{src.stem}_later.laz", **change)
    _ok(home, "init")
    _ok(home, "site", "create", name, "--crs", crs, "--origin", *map(str, origin))
    for path, when in zip((src, later), dates or (None, None), strict=True):
        _ok(home, "ingest", str(path), "--site", name, *ingest, *(("--captured-at", when) if when else ()))
    return home


def _images(root: Path, side: str) -> list[np.ndarray]:
    return [np.asarray(Image.open(p).convert("RGB")) for p in sorted(root.glob(f"*/{side}/*.png"))]


@pytest.fixture(scope="module")
def autzen(tmp_path_factory) -> Path:
    c = centre_xy(AUTZEN)  # feet
    change = {"removed_box": (c[0] - 250, c[1] - 100, c[0] - 150, c[1]),
              "built_box": (c[0] + 100, c[1] - 50, c[0] + 180, c[1] + 30, 20.0),
              "shift": (1.8 / 0.3048, -1.2 / 0.3048, 0.4 / 0.3048),  # 2.2 m off, as epochs of two flights
              "reclass": {1: 5}}  # and another vendor's scheme: what was unclassified is vegetation  # fmt: skip
    # its GPS times are week seconds: the file cannot tell its date, so the test gives one
    return _site(tmp_path_factory.mktemp("autzen"), "autzen", AUTZEN, "EPSG:32610", (493000, 4878000, 130), change,
                 dates=AUTZEN_DATES, ingest=("--overlap", "0.5", "0.3"))  # fmt: skip


def test_a_file_that_cannot_tell_its_date_is_refused(autzen, tmp_path) -> None:
    """autzen's GPS times are seconds of an unnamed week: no date without --captured-at (its header's
    creation day is when the file was written), exit 2 naming the file; nothing is added."""
    before = _ok(autzen, "scene", "list", "--site", "autzen", "--json")
    listing = sorted((autzen / "stores").rglob("*"))
    copy = tmp_path / "again.laz"
    later_epoch(AUTZEN, copy, days=90)
    r = _run(autzen, "ingest", str(copy), "--site", "autzen")
    assert r.returncode == 2 and "seconds of an unnamed GPS week" in r.stderr and "--captured-at" in r.stderr
    assert "again.laz" in r.stderr
    assert _ok(autzen, "scene", "list", "--site", "autzen", "--json") == before
    assert sorted((autzen / "stores").rglob("*")) == listing  # no blob, and no empty blob folder, left
    # a partition folder an ingest killed after its commit was writing (its pid is dead) goes at the
    # next ingest or tiling
    from siteline.stores.owners import owner_tag

    host, _, token = owner_tag().split("+")
    stale = autzen / "partitions" / f".new-{host}+999999999+{token}"
    stale.mkdir(parents=True)
    (stale / "run-00000.bin").write_bytes(b"x" * 1000)
    assert "already" in _ok(
        autzen, "ingest", str(AUTZEN), "--site", "autzen", "--captured-at", AUTZEN_DATES[0]
    )
    assert not stale.exists()


def test_an_epoch_metres_off_is_co_registered_and_its_tiles_corrected(autzen) -> None:
    """The later epoch lies 2.2 m off (1.8, -1.2, 0.4 m in the file's feet): ingest registers it onto
    the first, applies the correction to its tiles (its unchanged points then coincide with the first
    scene's) and records it; the release's changes are the planted ones, not the offset."""
    from scipy.spatial import cKDTree

    from siteline.tiles.reader import SceneTiles

    align = json.loads(_ok(autzen, "scene", "show", "2", "--json"))["registration"]["alignment"]
    assert align["applied"] and 2.1 < align["translation_m"] < 2.3 and align["residual_m"] < 0.05
    stores = [json.loads(_ok(autzen, "scene", "show", str(i), "--json"))["tile_store"] for i in (1, 2)]
    first, later = (SceneTiles.open(uri) for uri in stores)
    pa, pb = (t.read({k: t.prefix(k) for k in t.by_tile}, ()).xyz_m for t in (first, later))
    d, _ = cKDTree(pa).query(pb)
    assert np.median(d) < 0.01 and (d < 0.05).mean() > 0.95  # the planted structure is the rest


def test_bare_laz_with_rgb_is_released_with_planned_cameras(autzen) -> None:
    scene = json.loads(_ok(autzen, "scene", "show", "1", "--json"))
    assert scene["capture_time_source"] == "given (--captured-at)"
    assert scene["registration"]["source"] == "planned" and scene["cameras"] > 20
    assert scene["z_unit"]["name"] == "foot"  # the WKT's unit, converted to metres
    assert scene["class_histogram"].get("ignore", 0) == 0  # ASPRS 1 is unclassified, not ignore
    assert scene["class_histogram"]["unclassified"] == 83_893 and scene["class_scheme"] == "asprs"
    r = _run(autzen, "release", "build", "--site", "autzen", "--name", "autzen-cd", "--views", "16",
             "--radius-ceiling", "0.5")  # fmt: skip
    assert r.returncode == 0, r.stderr
    # a site that wants 0.5 m changes is told this 1.9 points/m2 survey cannot resolve them
    assert "is above the radius ceiling 0.50 m: a change smaller than" in r.stderr, r.stderr
    # the differing schemes are stated before any pair is processed, with the rule they lead to
    assert "classify differently" in r.stderr and "vegetation is 75.6% of scene 2" in r.stderr, r.stderr
    assert "geometry rule" in r.stderr and "--change-rule semantic" in r.stderr
    _ok(autzen, "release", "publish", "autzen-cd", "1.0.0")
    _ok(autzen, "release", "verify", "autzen-cd", "1.0.0")
    shown = json.loads(_ok(autzen, "release", "show", "autzen-cd", "1.0.0", "--json"))
    assert shown["radius_ceiling_m"] == 0.5 and 0.5 < shown["smallest_change_m"]["1"] < 1.5
    # the planted 24 x 24 x 6 m structure is one region (its roof's points lie 0.7 m apart: 0.5 m cells
    # cut it into 39 pieces of 17 m2 at most; cells of the change radius link it) views were planned
    # around, listed with the views that show it, in the record and in words (the clearing is a hole
    # in the data: not observed, not changed)
    seen = shown["changes_seen"]["1"]
    (built,) = [r for r in seen["regions"] if r["size_m"][0] > 20 and r["size_m"][1] > 20]
    assert seen["asked_views"] == 5 and 300 <= built["area_m2"] <= 1300 and len(built["views"]) >= 5, seen
    assert all(len(r["views"]) >= 5 or r["reason"] for r in seen["regions"])
    words = _ok(autzen, "release", "show", "autzen-cd", "1.0.0")
    assert "changes seen, pair 1" in words and "changed regions of 1 m2 or more" in words
    root = autzen / "releases" / "autzen-cd" / "1.0.0"
    manifest = json.loads((root / "manifest.json").read_text())
    (pair,) = manifest["lineage"]["pairs"]
    assert pair["colour_source"] == "rgb" and pair["fence"] == "footprint of scene 2"
    assert pair["change_rule"]["rule"] == "geometry" and len(pair["change_rule"]["differences"]) == 2
    assert manifest["lineage"]["parameters"]["change_rule"] == "auto"
    assert {s["registration"]["source"] for s in manifest["lineage"]["scenes"]} == {"planned"}
    items = manifest["items"]
    assert len(items) >= 8 and all(it["valid"] >= 0.25 for it in items)
    assert {it["split"] for it in items} == {"train", "val", "test"}  # one pair, every split populated
    assert "spatial bands" in manifest["split_rule"]["rule"]
    a, b = _images(root, "A"), _images(root, "B")
    assert len(a) == len(b) == len(items)
    assert min(img.any(axis=-1).mean() for img in a + b) > 0.2  # no blank image
    assert max(it["change_ratio"] for it in items) > 0.01  # the planted structure is seen
    # not the 2.2 m offset (uncorrected, at r = 0.9 m nearly every pixel would be changed)
    assert np.median([it["change_ratio"] for it in items]) < 0.1
    assert "co-registered onto scene 1" in (root / "README.md").read_text()
    assert "changes seen: " in (root / "README.md").read_text()
    assert "planned" in (root / "README.md").read_text()
    readme = (root / "README.md").read_text()
    assert "change rule geometry (the scenes classify differently (auto)): vegetation is 75.6%" in readme
    assert "ABOVE the radius ceiling of 0.50 m" in readme


@pytest.mark.slow  # 16 s: two more ingests of the real cloud; `make test-all` runs it
def test_codes_the_taxonomy_does_not_map_are_refused_or_ignored(autzen, tmp_path) -> None:
    """A file with codes the site taxonomy lacks (29: reserved by ASPRS) is refused, exit 2, naming the
    codes, their points and the scheme; nothing is added. --unmapped-codes ignore takes it, its
    points made ignore and the codes recorded."""
    import laspy

    las = laspy.read(AUTZEN)
    codes = np.asarray(las.classification).copy()
    codes[:500] = 29  # LAS 1.2 holds codes 0-31; the default taxonomy maps none of 28-31
    las.classification = codes
    odd = tmp_path / "odd.laz"
    las.write(odd)
    before = _ok(autzen, "scene", "list", "--site", "autzen", "--json")
    r = _run(autzen, "ingest", str(odd), "--site", "autzen", "--captured-at", "2021-01-01T00:00:00Z")
    assert r.returncode == 2 and "class codes 29 (500 points) are not mapped" in r.stderr, r.stderr
    assert (
        "odd.laz" in r.stderr
        and "custom classification" in r.stderr
        and "--unmapped-codes ignore" in r.stderr
    )
    assert _ok(autzen, "scene", "list", "--site", "autzen", "--json") == before
    home = tmp_path / "home"
    _ok(home, "init")
    _ok(home, "site", "create", "odd", "--crs", "EPSG:32610", "--origin", "493000", "4878000", "130")
    _ok(
        home,
        "ingest",
        str(odd),
        "--site",
        "odd",
        "--unmapped-codes",
        "ignore",
        "--captured-at",
        "2021-01-01T00:00:00Z",
    )
    scene = json.loads(_ok(home, "scene", "show", "1", "--json"))
    assert scene["class_histogram"]["ignore"] == 500 and scene["unknown_codes"] == {"29": 500}


def test_infeasible_settings_are_refused_before_any_view(autzen) -> None:
    """1 px fixed disks at 1/8 scale cover a few percent of autzen's sparse surfaces: refused at
    once (world splats, the default, draw each point as wide as its spacing and cover them)."""
    t0 = time.perf_counter()
    r = _run(
        autzen, "release", "build", "--site", "autzen", "--name", "paper", "--scale", "0.125", "--point-size", "1",
        "--splat", "fixed",
    )  # fmt: skip
    took = time.perf_counter() - t0
    assert r.returncode == 2 and took < 10.0, (r.returncode, took, r.stderr)
    assert "--point-size 5" in r.stderr and "min-coverage" in r.stderr
    assert not (autzen / "releases" / "paper").exists()
    t0 = time.perf_counter()
    r = _run(autzen, "release", "build", "--site", "autzen", "--name", "many", "--views", "5000")
    assert r.returncode == 2 and time.perf_counter() - t0 < 10.0, r.stderr
    assert "can give at most" in r.stderr and "fewer than --views 5000" in r.stderr


@pytest.mark.slow  # 29 s: a second real cloud ingested and released twice; `make test-all` runs it
def test_cloud_without_rgb_renders_height_with_edl_and_refuses_rgb(tmp_path) -> None:
    c = centre_xy(TOPOGRAPHY)
    change = {"removed_box": (c[0] - 60, c[1] - 60, c[0] - 20, c[1] - 20),
              "built_box": (c[0] + 30, c[1] + 30, c[0] + 70, c[1] + 60, 8.0), "days": 400}  # fmt: skip
    home = _site(tmp_path, "topo", TOPOGRAPHY, "EPSG:2949", (273500, 5274500, 800), change,
                 ingest=("--overlap", "0.5", "0.3", "--altitude", "100"))  # fewer planned cameras  # fmt: skip
    scene = json.loads(_ok(home, "scene", "show", "1", "--json"))
    assert scene["colour"] == "none"
    # adjusted standard GPS time: the date is the file's, less the 18 leap seconds of 2018
    assert scene["capture_time"].startswith("2018-09-07T14:56:02.8")
    assert scene["capture_time_source"] == "las gps time (adjusted standard)"
    survey = scene["registration"]["survey"]
    assert (survey["forward_overlap"], survey["side_overlap"], survey["altitude_m"]) == (0.5, 0.3, 100.0)
    r = _run(home, "release", "build", "--site", "topo", "--name", "rgb", "--colour", "rgb", "--views", "4")
    assert r.returncode == 2 and "carry no colour" in r.stderr
    _ok(home, "release", "build", "--site", "topo", "--name", "topo-cd", "--views", "4")
    root = home / "releases" / "topo-cd" / ".drafts" / "1.0.0"
    (pair,) = json.loads((root / "manifest.json").read_text())["lineage"]["pairs"]
    # 41 m of relief over 285 m: the views stand on a terrain grid, and the datasheet says so
    assert pair["ground"]["model"] == "terrain" and pair["ground"]["source"] == "class"
    assert pair["ground"]["residual_m"] > 1.0
    assert "views stand on a terrain grid" in (root / "README.md").read_text()
    # no RGB: the height above the ground on the ramp
    assert pair["colour"]["source"] == "height" and "shading" not in pair["colour"]
    assert "colour from height" in (root / "README.md").read_text()
    a = _images(root, "A")
    assert a and min(img.any(axis=-1).mean() for img in a) > 0.2
    ramp = np.concatenate([img.reshape(-1, 3) for img in a])
    assert not np.array_equal(ramp[:, 0], ramp[:, 1])  # a colour ramp, not grey
    # intensity as asked, with eye-dome lighting: grey, shaded
    _ok(
        home,
        "release",
        "build",
        "--site",
        "topo",
        "--name",
        "grey",
        "--views",
        "4",
        "--colour",
        "intensity",
        "--shading",
        "edl",
    )
    grey = np.concatenate(
        [img.reshape(-1, 3) for img in _images(home / "releases" / "grey" / ".drafts" / "1.0.0", "A")]
    )
    assert np.array_equal(grey[:, 0], grey[:, 1])


@pytest.mark.slow  # 25 s: two ingests and two builds; `make test-all` runs it
def test_black_colour_is_refused_at_build_never_published(tmp_path) -> None:
    """RGB that varies in one point only (the rest black) passes the scan's check, so auto takes RGB;
    the build then finds every image blank and refuses, naming the fix, with nothing written."""
    import laspy

    src = tmp_path / "black.laz"
    las = laspy.read(AUTZEN)
    c = centre_xy(AUTZEN)
    las.points = las.points[
        (np.abs(np.asarray(las.x) - c[0]) < 200) & (np.abs(np.asarray(las.y) - c[1]) < 150)
    ]
    for ch in ("red", "green", "blue"):
        values = np.zeros(len(las.points), np.uint16)
        values[0] = 255
        setattr(las, ch, values)
    las.write(src)
    home = _site(tmp_path, "black", src, "EPSG:32610", (493000, 4878000, 130),
                 {"built_box": (c[0] + 50, c[1] - 50, c[0] + 130, c[1] + 30, 20.0)}, AUTZEN_DATES,
                 ingest=("--overlap", "0.5", "0.3"))  # fmt: skip
    r = _run(home, "release", "build", "--site", "black", "--name", "black-cd", "--views", "4")
    assert r.returncode == 2 and "blank images" in r.stderr and "--colour intensity" in r.stderr
    assert not (home / "releases" / "black-cd" / ".drafts" / "1.0.0").exists()
    _ok(
        home,
        "release",
        "build",
        "--site",
        "black",
        "--name",
        "black-cd",
        "--views",
        "2",
        "--colour",
        "intensity",
    )


def _small_dense_site(path: Path, density: float = 400.0, seed: int = 0) -> Path:
    """A 40 x 32 m scan at ``density`` points/m2 (UTM 18N): rough ground (class 2) with colour and a
    6 x 6 m, 4 m high building (class 6), as a pilot's low flight over a small plot gives."""
    import laspy

    rng = np.random.default_rng(seed)
    x0, y0 = 445_100.0, 5_030_100.0
    n = int(40 * 32 * density)
    xy = rng.uniform((0, 0), (40, 32), (n, 2))
    z = 80.0 + 0.05 * rng.standard_normal(n)
    cls = np.full(n, 2, np.uint8)
    roof = (np.abs(xy[:, 0] - 12) < 3) & (np.abs(xy[:, 1] - 16) < 3)
    z[roof] += 4.0
    cls[roof] = 6
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales, header.offsets = np.array([0.001] * 3), np.array([x0, y0, 0.0])
    las = laspy.LasData(header)
    las.x, las.y, las.z = xy[:, 0] + x0, xy[:, 1] + y0, z
    las.classification = cls
    shade = (96 + 64 * np.sin(xy[:, 0] / 3.0) * np.cos(xy[:, 1] / 4.0) + 20 * rng.random(n)).astype(np.uint16)
    las.red, las.green, las.blue = shade * 256, (shade + 30) * 256, (shade // 2) * 256
    las.gps_time = np.linspace(0.0, 600.0, n)
    las.write(path)
    return path


@pytest.mark.slow  # 2-4 min: two 512k-point ingests and a release with every default; `make test-all` runs it
def test_a_small_dense_site_gets_a_release_with_defaults(tmp_path) -> None:
    src = _small_dense_site(tmp_path / "plot.las")
    home = _site(tmp_path, "plot", src, "EPSG:32618", (445_100.0, 5_030_100.0, 80.0),
                 {"removed_box": (445_125.0, 5_030_105.0, 445_131.0, 5_030_111.0),
                  "built_box": (445_125.0, 5_030_105.0, 445_131.0, 5_030_111.0, 3.0)},
                 dates=("2024-05-01T10:00:00Z", "2024-05-15T10:00:00Z"), ingest=("--crs", "EPSG:32618"))  # fmt: skip
    scene = json.loads(_ok(home, "scene", "show", "2", "--json"))
    survey = scene["registration"]["survey"]
    assert survey["altitude_m"] < 80.0 and scene["cameras"] >= 16  # flown low enough for its views
    r = _run(home, "release", "build", "--site", "plot", "--name", "plot-cd", "--publish")
    assert r.returncode == 0, r.stderr
    manifest = json.loads((home / "releases" / "plot-cd" / "1.0.0" / "manifest.json").read_text())
    assert len(manifest["items"]) >= 30 and {it["split"] for it in manifest["items"]} == {
        "train",
        "val",
        "test",
    }
    assert max(it["change_ratio"] for it in manifest["items"]) > 0.01


@pytest.mark.slow  # about 5 min here: two ingests, a release with default settings; `make test-all` runs it
def test_a_cloud_without_a_ground_class_is_released_with_defaults(tmp_path) -> None:
    """autzen with every class zeroed (a scanner's raw export) and an edited copy of it (a building
    removed, one built, classes zero too): the release finds the ground from the points' shape, says
    so, and gives at least 24 items, none blank."""
    import laspy

    src = tmp_path / "autzen_raw.laz"
    las = laspy.read(AUTZEN)
    las.classification = np.zeros(len(las.points), np.uint8)
    las.write(src)
    c = centre_xy(AUTZEN)
    change = {"removed_box": (c[0] - 250, c[1] - 100, c[0] - 150, c[1]),
              "built_box": (c[0] + 100, c[1] - 50, c[0] + 180, c[1] + 30, 20.0), "reclass": {6: 0}}  # fmt: skip
    home = _site(tmp_path, "raw", src, "EPSG:32610", (493000, 4878000, 130), change, AUTZEN_DATES,
                 ingest=("--overlap", "0.5", "0.3"))  # fmt: skip
    assert json.loads(_ok(home, "scene", "show", "2", "--json"))["class_histogram"].get("ground", 0) == 0
    _ok(home, "release", "build", "--site", "raw", "--name", "raw-cd")
    root = home / "releases" / "raw-cd" / ".drafts" / "1.0.0"
    manifest = json.loads((root / "manifest.json").read_text())
    (pair,) = manifest["lineage"]["pairs"]
    # its levee: the ground rises above the best plane by about 1.2 m (95th percentile), near the 1 m
    # tolerance: whichever model, the record says why
    g = pair["ground"]
    assert g["source"] == "morphology" and g["model"] == (
        "terrain" if g["residual_m"] > g["tolerance_m"] else "plane"
    )
    assert 0.2 < pair["ground"]["share"] < 0.95
    assert "ground found from the points' shape" in (root / "README.md").read_text()
    a, b = _images(root, "A"), _images(root, "B")
    assert len(a) == len(b) >= 24
    assert min(img.any(axis=-1).mean() for img in a + b) > 0.2  # no blank image
