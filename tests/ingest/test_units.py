"""Missions in feet: any source CRS is converted into the metre site CRS, z included; sites refuse a
feet CRS and name the metric one to use."""

from __future__ import annotations

import json
from pathlib import Path

import laspy
import numpy as np
import pyproj
import pytest
from sitehelpers import run_cli

from siteline.errors import CRSError
from siteline.site.crs import parse_z_unit, z_unit_of

OREGON_FT = "EPSG:2994"  # NAD83(HARN) / Oregon GIC Lambert (ft), the CRS of laspy's autzen sample
OREGON_FT_COMPOUND = "EPSG:2994+6360"  # ... + NAVD88 height (ftUS)
UTM = "EPSG:32610"
US_FT = 1200.0 / 3937.0


@pytest.fixture
def ft_home(tmp_path, monkeypatch, capsys) -> Path:
    """A fresh SITELINE_HOME with an initialised catalog and no site."""
    home = tmp_path / "home"
    monkeypatch.setenv("SITELINE_HOME", str(home))
    monkeypatch.delenv("SITELINE_DATABASE_URL", raising=False)
    monkeypatch.delenv("SITELINE_STORE_URL", raising=False)
    assert run_cli(capsys, "init")[0] == 0
    return home


def _autzen_like(n: int = 4000, seed: int = 0) -> np.ndarray:
    """(n, 3) float64 points over autzen's footprint, in feet (x, y Oregon Lambert ft; z 406-520 ft)."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(636_000.0, 636_300.0, n)
    y = rng.uniform(849_000.0, 849_300.0, n)
    z = 406.0 + 114.0 * rng.random(n)
    return np.round(np.c_[x, y, z], 2)


def _mission(root: Path, xyz: np.ndarray, crs: str | None) -> Path:
    """A LiDAR-only mission folder: a LAS 1.4 file (CRS recorded as WKT when given, else none)."""
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.array([0.01, 0.01, 0.01])
    header.offsets = np.floor(xyz.min(axis=0))
    if crs is not None:
        header.add_crs(pyproj.CRS.from_user_input(crs))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.gps_time = np.arange(len(xyz), dtype=np.float64)
    las.classification = np.full(len(xyz), 2, np.uint8)
    path = root / "lidars" / "terra_las" / "cloud_merged.las"
    path.parent.mkdir(parents=True)
    las.write(path)
    return root


def _utm_site(capsys, xyz_ft: np.ndarray, name: str = "oregon") -> np.ndarray:
    centre = xyz_ft.mean(axis=0)
    tr = pyproj.Transformer.from_crs(OREGON_FT, UTM, always_xy=True)
    ox, oy = tr.transform(centre[0], centre[1])
    origin = np.array([round(ox), round(oy), 130.0])
    code, _, err = run_cli(capsys, "site", "create", name, "--crs", UTM, "--origin", *map(str, origin))
    assert code == 0, err
    return origin


def _export(capsys, tmp_path: Path, scene_id: int) -> laspy.LasData:
    out = tmp_path / f"scene{scene_id}.laz"
    code, _, err = run_cli(capsys, "scene", "export", str(scene_id), "--out", str(out))
    assert code == 0, err
    return laspy.read(out)


def _expected_m(xyz_ft: np.ndarray, z_metres_per_unit: float) -> np.ndarray:
    tr = pyproj.Transformer.from_crs(OREGON_FT, UTM, always_xy=True)
    x, y = tr.transform(xyz_ft[:, 0], xyz_ft[:, 1])
    return np.c_[x, y, xyz_ft[:, 2] * z_metres_per_unit]


def _check_round_trip(las: laspy.LasData, xyz_ft: np.ndarray, z_metres_per_unit: float) -> None:
    order = np.argsort(np.asarray(las.gps_time))
    got = np.c_[np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)][order]
    want = _expected_m(xyz_ft, z_metres_per_unit)
    assert len(got) == len(want)
    # tile quantum 1 mm, rounded once into the tiles and once into the export
    assert np.abs(got - want).max() <= 1e-3 + 1e-9
    assert 123.0 < got[:, 2].min() and got[:, 2].max() < 159.0  # 406-520 ft are 124-158 m


def _ingest_and_show(capsys, mission: Path, *extra: str) -> tuple[int, dict]:  # noqa: ANN001
    """``siteline ingest`` the mission into site oregon; return its scene id and ``scene show``."""
    code, out, err = run_cli(
        capsys,
        "ingest",
        str(mission),
        "--site",
        "oregon",
        "--captured-at",
        "2024-06-01T12:00:00Z",
        *extra,
        "--json",
    )
    assert code == 0, err
    scene = json.loads(out)["scene_id"]
    code, out, _ = run_cli(capsys, "scene", "show", str(scene), "--json")
    return scene, json.loads(out)


def test_feet_lidar_in_a_utm_site_comes_back_in_metres(ft_home, capsys, tmp_path) -> None:
    xyz = _autzen_like()
    _utm_site(capsys, xyz)
    scene, shown = _ingest_and_show(capsys, _mission(tmp_path / "m1", xyz, OREGON_FT))
    assert shown["z_unit"] == {"name": "foot", "metres": 0.3048, "source": "horizontal unit"}
    assert shown["transformed"] is True
    _check_round_trip(_export(capsys, tmp_path, scene), xyz, 0.3048)


def test_compound_crs_in_us_survey_feet_converts_z_from_its_vertical_crs(ft_home, capsys, tmp_path) -> None:
    xyz = _autzen_like(seed=1)
    _utm_site(capsys, xyz)
    scene, shown = _ingest_and_show(capsys, _mission(tmp_path / "m2", xyz, OREGON_FT_COMPOUND))
    assert shown["z_unit"]["source"] == "vertical CRS"
    assert shown["z_unit"]["metres"] == pytest.approx(US_FT, rel=1e-15)
    _check_round_trip(_export(capsys, tmp_path, scene), xyz, US_FT)


def test_crs_option_in_feet_is_accepted_and_z_unit_overrides(ft_home, capsys, tmp_path) -> None:
    xyz = _autzen_like(seed=2)
    _utm_site(capsys, xyz)
    mission = _mission(tmp_path / "m3", xyz, None)
    scene, shown = _ingest_and_show(capsys, mission, "--crs", OREGON_FT, "--z-unit", "ftUS")
    assert shown["z_unit"] == {"name": "US survey foot", "metres": US_FT, "source": "--z-unit"}
    _check_round_trip(_export(capsys, tmp_path, scene), xyz, US_FT)


def test_site_in_a_feet_crs_is_refused_naming_a_metric_crs(ft_home, capsys) -> None:
    code, _, err = run_cli(
        capsys, "site", "create", "ft", "--crs", OREGON_FT, "--origin", "636000", "849000", "0"
    )
    assert code == 2
    assert "foot" in err and "EPSG:26910" in err and "--z-unit" in err


def test_z_unit_rules() -> None:
    assert z_unit_of(pyproj.CRS(OREGON_FT)).metres == 0.3048
    assert z_unit_of(pyproj.CRS(OREGON_FT_COMPOUND)).name == "US survey foot"
    assert z_unit_of(pyproj.CRS("EPSG:32618")).metres == 1.0
    assert z_unit_of(pyproj.CRS("EPSG:4979")).metres == 1.0  # ellipsoidal height in metres
    assert z_unit_of(pyproj.CRS(OREGON_FT), parse_z_unit("m")).source == "--z-unit"
    with pytest.raises(CRSError, match="--z-unit 'yards'"):
        parse_z_unit("yards")


def test_a_feet_wkt_site_crs_is_refused_briefly_naming_the_utm_zone_of_the_origin() -> None:
    """A feet CRS given as WKT (no EPSG code, no area of use): the refusal names it by its name, once,
    and suggests the UTM zone of the site origin, not 'EPSG:326xx'."""
    import laspy
    from realdata import AUTZEN

    from siteline.errors import CRSError
    from siteline.site.spec import make_site_spec

    wkt = laspy.read(AUTZEN).header.parse_crs().to_wkt()
    with pytest.raises(CRSError) as err:
        make_site_spec("x", wkt, (636590.0, 849216.0, 400.0))
    text = str(err.value)
    assert "EPSG:26910" in text and "326xx" not in text and "PROJCRS" not in text
    assert text.count("NAD_1983_HARN_Lambert_Conformal_Conic") == 1


def test_a_header_crs_its_coordinates_disprove_is_refused_and_overridden_by_crs(tmp_path) -> None:
    """A header that says WGS 84 over projected coordinates: refused saying why (not 'non-finite
    coordinates'); --crs then overrides it."""
    import laspy
    from pyproj import CRS
    from realdata import AUTZEN

    from siteline.errors import CRSError
    from siteline.pointpass import source_crs

    src = laspy.read(AUTZEN)
    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
    las.header.offsets, las.header.scales = src.header.offsets, src.header.scales
    las.header.add_crs(CRS.from_epsg(4326))
    las.points = src.points[:2000]
    path = tmp_path / "wrong.las"
    las.write(path)
    with pytest.raises(CRSError, match="wrong.las.*WGS 84 is in degrees, but x reaches 63"):
        source_crs(path, None)
    assert source_crs(path, "EPSG:2994").to_epsg() == 2994
    assert source_crs(AUTZEN, None).name == "NAD_1983_HARN_Lambert_Conformal_Conic"  # a right header stays
