"""Small real public LAS files as users hold them (tests/data/real/laspy_*): each one either ingests,
tiles and exports back exactly, or is refused with one line naming the file. A scene no survey can
be planned over (a 2 m patch, a thousand points over a square kilometre) is still a scene: it
ingests with no cameras and a note, and only a release says it gives no views, naming it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pyproj
import pytest
from scipy.spatial import cKDTree

REAL = Path(__file__).resolve().parents[1] / "data" / "real"
SITELINE = str(Path(sys.executable).parent / "siteline")
WHEN = "2021-01-01T00:00:00Z"

# file, the CRS it is in when it names none, the site's metric CRS; None: refused (what the line says).
# The clouds spread over a square kilometre tile into hundreds of 50 m tiles: `make test-all` runs them
WIDE = pytest.mark.slow
FILES = [
    ("laspy_plane.laz", "EPSG:3857", "EPSG:3857", None),
    pytest.param("laspy_simple.las", "EPSG:2992", "EPSG:32610", None, marks=WIDE),
    pytest.param("laspy_autzen.las", None, "EPSG:32610", None, marks=WIDE),
    ("laspy_vegetation_1_3.las", "EPSG:3857", "EPSG:3857", None),
    pytest.param("laspy_test1_4.las", None, "EPSG:32613", None, marks=WIDE),
    ("laspy_simple1_3.las", "EPSG:3857", "EPSG:3857", "header counts 999 points but the file holds 1,001"),
]


def _run(home: Path, *args: str) -> subprocess.CompletedProcess:
    env = os.environ | {"SITELINE_HOME": str(home)}
    env.pop("SITELINE_DATABASE_URL", None)
    return subprocess.run([SITELINE, *args], capture_output=True, text=True, env=env, timeout=600)


def _site_xyz(path: Path, file_crs: str | None, site_crs: str) -> np.ndarray:
    """The file's points in the site CRS, metres (float64)."""
    las = laspy.read(path)
    xyz = np.c_[las.x, las.y, las.z]
    src = pyproj.CRS(file_crs) if file_crs else las.header.parse_crs()
    if src.equals(pyproj.CRS(site_crs)):
        return xyz
    tr = pyproj.Transformer.from_crs(src, site_crs, always_xy=True)
    x, y = tr.transform(xyz[:, 0], xyz[:, 1])
    unit = src.axis_info[0].unit_conversion_factor
    return np.c_[x, y, xyz[:, 2] * unit]


def _duplicates(xyz: np.ndarray) -> int:
    """How many points repeat another's position exactly (a nearest-point match cannot tell them apart)."""
    return len(xyz) - len(np.unique(xyz, axis=0))


@pytest.mark.parametrize(("name", "file_crs", "site_crs", "refused"), FILES)
def test_a_small_real_file_ingests_and_exports_back_or_is_refused_naming_it(
    tmp_path, name, file_crs, site_crs, refused
) -> None:
    path = REAL / name
    home = tmp_path / "home"
    assert _run(home, "init").returncode == 0
    if refused:
        origin = ["0", "0", "0"]
    else:
        xyz = _site_xyz(path, file_crs, site_crs)
        origin = [f"{v:.3f}" for v in (xyz.min(axis=0) + xyz.max(axis=0)) / 2]
    assert _run(home, "site", "create", "s", "--crs", site_crs, "--origin", *origin).returncode == 0
    crs = ["--crs", file_crs] if file_crs else []
    r = _run(home, "ingest", str(path), "--site", "s", *crs, "--captured-at", WHEN)
    if refused:
        assert r.returncode == 2 and str(path) in r.stderr and refused in r.stderr, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1
        return
    assert r.returncode == 0, r.stderr
    scene = json.loads(_run(home, "scene", "show", "1", "--json").stdout)
    out = tmp_path / "back.laz"
    assert _run(home, "scene", "export", "1", "--out", str(out)).returncode == 0
    back = laspy.read(out)
    got = np.c_[back.x, back.y, back.z]
    want = _site_xyz(path, file_crs, site_crs)
    assert len(got) == len(want) == scene["point_count"]
    # the tile quantum is 1 mm: every point comes back within it, one for one
    d, j = cKDTree(want).query(got)
    assert d.max() <= 0.0011 * np.sqrt(3) and len(np.unique(j)) == len(want) - _duplicates(want)


@pytest.mark.slow  # 14 s: two real-file ingests and a release attempt; `make test-all` runs it
def test_a_scene_no_survey_covers_ingests_and_a_release_refuses_naming_it(tmp_path) -> None:
    home = tmp_path / "home"
    _run(home, "init")
    _run(home, "site", "create", "patch", "--crs", "EPSG:3857", "--origin", "1423215", "4189097", "67")
    first = _run(
        home,
        "ingest",
        str(REAL / "laspy_plane.laz"),
        "--site",
        "patch",
        "--crs",
        "EPSG:3857",
        "--captured-at",
        WHEN,
    )
    assert first.returncode == 0 and "no cameras" in first.stdout and "no survey position" in first.stdout, (
        first.stdout
    )
    las = laspy.read(REAL / "laspy_plane.laz")
    x, y = np.asarray(las.x), np.asarray(las.y)
    corner = (x > np.quantile(x, 0.75)) & (y > np.quantile(y, 0.75))
    las.z = np.asarray(las.z) + np.where(corner, 0.5, 0.0)  # a corner raised
    later = tmp_path / "plane_later.laz"
    las.write(later)
    second = _run(
        home,
        "ingest",
        str(later),
        "--site",
        "patch",
        "--crs",
        "EPSG:3857",
        "--captured-at",
        "2021-02-01T00:00:00Z",
    )
    assert second.returncode == 0, second.stderr
    scene = json.loads(_run(home, "scene", "show", "2", "--json").stdout)
    assert scene["cameras"] == 0 and "no survey position" in scene["registration"]["note"]
    r = _run(home, "release", "build", "--site", "patch", "--name", "patch-cd")
    assert r.returncode == 2, r.stderr
    assert (
        "pair 1 gives no views: its later scene 2 has no cameras" in r.stderr
        and "no survey position" in r.stderr
    )
    assert not (home / "releases" / "patch-cd").exists()
