"""Site inputs are validated before anything is written."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from siteline.errors import CRSError, GeometryError, SchemaError, SiteError
from siteline.site.crs import parse_crs, site_from_crs
from siteline.site.fence import inside_fence, load_fence_geojson, nearest_segment, validate_fence
from siteline.site.spec import SiteSpec, make_site_spec
from siteline.site.taxonomy import default_taxonomy, load_taxonomy

SQUARE = [(0, 0), (100, 0), (100, 80), (0, 80), (0, 0)]


@pytest.mark.parametrize("crs", ["EPSG:999999", "not a crs", "", "EPSG:4326"])
def test_bad_crs_is_refused(crs: str) -> None:
    with pytest.raises(CRSError):
        make_site_spec("s", crs, (0, 0, 0))


def test_wkt_crs_canonicalises_to_epsg() -> None:
    wkt = parse_crs("EPSG:32618").to_wkt()
    assert make_site_spec("s", wkt, (0, 0, 0)).crs == "EPSG:32618"


@pytest.mark.parametrize(
    "origin", [(math.nan, 0, 0), (0, math.inf, 0), (0, 0, -math.inf), (1e12, 0, 0), (0, 0)]
)
def test_bad_origin_is_refused(origin) -> None:
    with pytest.raises(GeometryError):
        make_site_spec("s", "EPSG:32618", origin)


def test_fence_not_closed_is_refused() -> None:
    with pytest.raises(GeometryError, match="not closed"):
        validate_fence(SQUARE[:-1])


def test_self_intersecting_fence_is_refused() -> None:
    bowtie = [(0, 0), (10, 10), (10, 0), (0, 10), (0, 0)]
    with pytest.raises(GeometryError, match="intersect"):
        validate_fence(bowtie)


def test_degenerate_fence_is_refused() -> None:
    with pytest.raises(GeometryError):
        validate_fence([(0, 0), (1, 1), (2, 2), (0, 0)])


def test_fence_geojson_in_crs_becomes_site_local(tmp_path) -> None:
    origin = (445000.0, 5030000.0, 80.0)
    ring = [[x + origin[0], y + origin[1]] for x, y in SQUARE]
    path = tmp_path / "fence.geojson"
    path.write_text(json.dumps({"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]}}))
    local = load_fence_geojson(path, origin)
    assert local == [(0.0, 0.0), (100.0, 0.0), (100.0, 80.0), (0.0, 80.0)]


def test_fence_geojson_in_wrong_frame_is_refused(tmp_path) -> None:
    path = tmp_path / "fence.geojson"
    path.write_text(json.dumps({"type": "Polygon", "coordinates": [SQUARE]}))
    with pytest.raises(GeometryError, match=str(path)):
        load_fence_geojson(path, (445000.0, 5030000.0, 80.0))


def test_inside_fence_and_nearest_segment() -> None:
    ring = validate_fence(SQUARE)
    inside = inside_fence(np.array([[50.0, 40.0], [150.0, 40.0], [100.0, 40.0]]), ring)
    assert inside.tolist() == [True, False, True]
    a, b = nearest_segment((50.0, 78.0), ring)
    assert {tuple(a), tuple(b)} == {(100.0, 80.0), (0.0, 80.0)}


def test_inside_fence_shortcut_for_covered_chunks_agrees_with_the_point_test() -> None:
    """An L-shaped fence: a chunk whose bounding box it covers is inside whole; one across the notch
    is tested point by point; both as shapely says (on the fence counts as inside)."""
    import shapely

    ring = validate_fence([(0, 0), (100, 0), (100, 40), (40, 40), (40, 100), (0, 100), (0, 0)])
    rng = np.random.default_rng(0)
    covered = rng.uniform([1, 1], [99, 39], (5_000, 2))
    across = rng.uniform([0, 0], [100, 100], (5_000, 2))
    assert inside_fence(covered, ring).all()
    want = shapely.intersects_xy(shapely.Polygon(ring), across[:, 0], across[:, 1])
    got = inside_fence(across, ring, tol_m=0.0)
    assert np.array_equal(got, want) and 0 < got.sum() < len(got)
    assert inside_fence(np.array([[100.0, 40.0], [40.0, 100.0]]), ring).all()  # on the fence


def test_taxonomy_failing_schema_names_file(tmp_path) -> None:
    bad = default_taxonomy().to_dict()
    bad["classes"][0]["id"] = 300
    path = tmp_path / "tax.json"
    path.write_text(json.dumps(bad))
    with pytest.raises(SchemaError, match=r"(?s)tax\.json.*classes/0/id"):
        load_taxonomy(path)


def test_taxonomy_mapping_to_unknown_class_is_refused(tmp_path) -> None:
    bad = default_taxonomy().to_dict()
    bad["source_codes"]["las"]["2"] = "lava"
    path = tmp_path / "tax.json"
    path.write_text(json.dumps(bad))
    with pytest.raises(SchemaError, match="lava"):
        load_taxonomy(path)


def test_taxonomy_luts() -> None:
    tax = default_taxonomy()
    lut, known = tax.code_lut("las")
    assert lut[2] == tax.id_of("ground") and known[2]
    assert lut[200] == tax.ignore_id and not known[200]
    ign = tax.ignored_lut()
    assert ign[tax.id_of("snow")] and ign[tax.id_of("noise")] and ign[255] and not ign[tax.id_of("crane")]


def test_site_spec_json_round_trip() -> None:
    spec = make_site_spec("s", "EPSG:32618", (445000.1, 5030000.2, 80.3), SQUARE)
    again = SiteSpec.from_dict(json.loads(json.dumps(spec.to_dict())))
    assert again == spec


def test_bad_site_name() -> None:
    with pytest.raises(SiteError):
        make_site_spec("../etc", "EPSG:32618", (0, 0, 0))


def test_site_from_crs_refuses_float32() -> None:
    with pytest.raises(GeometryError, match="float64"):
        site_from_crs(np.zeros((2, 3), np.float32), (0, 0, 0))


def test_footprint_follows_the_data() -> None:
    """A scene's footprint is a fence ring around an L-shaped cloud that leaves the notch out."""
    import numpy as np
    import shapely

    from siteline.site.fence import footprint, inside_fence

    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 100, (20_000, 2))
    pts = pts[~((pts[:, 0] > 50) & (pts[:, 1] > 50))]  # an L: the north-east quarter is empty
    ring = footprint(pts)
    assert ring is not None and shapely.Polygon(ring).is_valid
    assert inside_fence(np.array([[25.0, 25.0], [25.0, 75.0], [75.0, 25.0]]), ring).all()
    assert not inside_fence(np.array([[85.0, 85.0]]), ring).any()
    assert 6_500 < shapely.Polygon(ring).area < 7_800  # the L is 7,500 m2
    assert footprint(np.zeros((10, 2))) is None  # no area
