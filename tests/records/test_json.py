"""JSON documents as types: the checked reads of a JSON value, the records' parsers that use them (a
document read back is the record written, and a wrong value is named), and the readers of recorded
parameters."""

from __future__ import annotations

import json

import numpy as np
import pytest

from siteline.camera.pinhole import Camera, CameraModel
from siteline.errors import ReleaseError, SchemaError
from siteline.records.pairs import ChangeLabels, Drawn, GroundUsed, RadiusChoice, RenderedView, ViewStrategy
from siteline.records.params.pairs import PairParams
from siteline.records.registration import Alignment, Registration, SurveyPlan
from siteline.records.release import ReleaseItem
from siteline.records.tiling import SceneTiling, TileSpec
from siteline.schema import (
    json_bool,
    json_int,
    json_list,
    json_number,
    json_numbers,
    json_object,
    json_or_none,
    json_str,
    validated,
)
from siteline.site.taxonomy import TaxonomyDoc, default_taxonomy


def test_checked_reads_take_their_kind_and_name_the_key_otherwise() -> None:
    assert json_object({"a": 1}) == {"a": 1}
    assert json_list([1, 2]) == [1, 2]
    assert json_numbers([1, 2.5]) == [1, 2.5]
    assert json_int(3) == 3 and json_int(3.0) == 3 and isinstance(json_int(3.0), int)
    assert json_str("x") == "x" and json_bool(False) is False
    # an int stays an int (a document read back and written again keeps its bytes)
    assert isinstance(json_number(2), int) and json_number(0.5) == 0.5
    assert json_or_none(json_int, None) is None and json_or_none(json_int, 4) == 4
    for read, bad in (
        (json_object, [1]),
        (json_list, "ab"),  # a string is a sequence, not a JSON array
        (json_list, {"a": 1}),
        (json_number, True),  # a bool is an int to Python, not a number to JSON
        (json_number, "1.5"),
        (json_int, 1.5),
        (json_int, False),
        (json_str, 3),
        (json_bool, 0),
    ):
        with pytest.raises(TypeError, match="the key"):
            read(bad, "the key")


def test_a_schema_checked_document_is_its_typed_dict_and_a_bad_one_is_named() -> None:
    doc = validated(default_taxonomy().to_dict(), "taxonomy.schema.json", "t", TaxonomyDoc)
    assert doc["classes"][0]["name"] == default_taxonomy().classes[0].name
    with pytest.raises(SchemaError, match="my file"):
        validated({"name": 3}, "taxonomy.schema.json", "my file", TaxonomyDoc)


def _camera() -> Camera:
    return Camera.from_pose(64, 48, 50.0, 51.0, 32.0, 24.0, np.eye(3), np.array([1.0, 2.0, 30.0]))


def _round_trip(record: object) -> object:
    """The record's document as a file holds it (JSON text), parsed back by its type's parser."""
    doc = json.loads(json.dumps(record.to_dict()))  # type: ignore[attr-defined]
    return type(record).from_dict(doc)  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    "record",
    [
        ViewStrategy(0.8, True, 0.2, ((0.0, 1.0), (2.0, 3.0)), "aim-site", 12.5, 2.5),
        ViewStrategy(1.0, False, 0.0),
        RadiusChoice(
            {"t1": 0.05, "t2": 0.07}, 2.5, True, {"per_direction": 0.01, "union": 0.02, "rule": "2^(-k^2)"}
        ),
        ChangeLabels(
            "labels/x",
            0.12,
            {"t1": {"changed": 3, "unchanged": 7}},
            "abc",
            1.5,
            10,
            RadiusChoice({"t1": 0.05}, 2.0),
        ),  # fmt: skip
        GroundUsed("terrain", "morphology", 120, 0.4, 0.3, 0.25, {"cell_m": 1.0, "slope": 0.3}, 2.0),
        SurveyPlan(altitude_m=60.0),
        Alignment(
            4,
            0.2,
            0.1,
            True,
            0.03,
            0.02,
            {"x": "structure", "y": None, "z": "ground"},
            ((1.0, 0.0, 0.0, 0.1),) * 4,
            True,
            0.01,
            "previous<-this",
            100,
            50,
            "ground",
            False,
            7,
            0.9,
            0.05,
        ),  # fmt: skip
        CameraModel("OPENCV", 640, 480, (500.0, 500.0, 320.0, 240.0, 0.01, 0.0, 0.0, 0.0)),
        TileSpec(tile_size_m=25.0, node_order="random"),
    ],
    ids=lambda r: type(r).__name__,
)
def test_a_record_read_back_from_its_json_is_the_record(record: object) -> None:
    assert _round_trip(record) == record


def test_rendered_views_registrations_and_tilings_read_back_whole() -> None:
    view = RenderedView(3, "IMG_1", "lowered", ViewStrategy(0.8, False, 0.0), 0.9, _camera(), "v3.png",
                        0.9, 0.8, 0.7, 0.1, 12345, {"gap": 0.05}, 0.01, 0.75, None)  # fmt: skip
    back = _round_trip(view)
    assert isinstance(back, RenderedView)
    assert back.camera.to_dict() == view.camera.to_dict()
    assert (back.index, back.file, back.points_read, back.ignore) == (3, "v3.png", 12345, {"gap": 0.05})
    reg = Registration("planned", images=12, survey=SurveyPlan(altitude_m=60.0), altitude_why="given",
                       residuals_m={"a": 0.1}, rms_m=0.1)  # fmt: skip
    assert _round_trip(reg) == reg
    tiling = SceneTiling("tiles/s1", TileSpec(), "sum", 2, 1000, 4, 6, 12_000, 1.5, 40, 9000, 3)
    assert _round_trip(tiling) == tiling


def test_a_registration_hands_out_its_survey_as_the_catalog_keeps_it() -> None:
    reg = Registration("planned", survey=SurveyPlan(altitude_m=60.0), altitude_why="10th percentile")
    assert reg.survey_record() == reg.to_dict()["survey"]
    assert reg.survey_record()["altitude_why"] == "10th percentile"  # type: ignore[index]
    assert Registration("xmp").survey_record() is None


@pytest.mark.parametrize(
    ("parse", "doc", "key"),
    [
        (
            ViewStrategy.from_dict,
            {"vertical_fraction": "high", "mirrored": False, "forward_fraction": 0},
            "vertical_fraction",
        ),
        (ChangeLabels.from_dict, {"radius_m": 0.1, "counts": {"t1": {"changed": "3"}}}, "counts.t1.changed"),
        (Drawn.from_dict, {"candidates": 4, "rejected": {"low_valid": 1.5}}, "rejected.low_valid"),
        (Alignment.from_dict, {"matched": "many"}, "matched"),
        (Registration.from_dict, {"source": "colmap", "rms_m": [0.1]}, "rms_m"),
        (SceneTiling.from_dict, {"uri": "t", "spec": {}, "checksum": "c", "points": "1000"}, "points"),
    ],
)
def test_a_wrong_value_is_named_by_its_key(parse, doc, key) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(TypeError, match=key.replace(".", r"\.")):
        parse(doc)


def test_a_manifest_item_with_a_bad_size_is_refused_naming_it() -> None:
    item = {"id": "p1_v0", "split": "train", "pair": 1, "view": 0, "coverage": 0.9, "change_ratio": 0.1,
            "valid": 0.8, "size_px": ["64", 48]}  # fmt: skip
    with pytest.raises(TypeError, match="integer"):
        ReleaseItem.from_dict(item)
    item["size_px"] = [64, 48]
    assert ReleaseItem.from_dict(item).padded_px == (64, 48)


def test_recorded_parameters_read_a_missing_knob_as_what_it_meant_before() -> None:
    now = PairParams()
    old = {
        k: v for k, v in now.to_dict().items() if k not in ("splat", "label_rule", "surface_probe", "sampler")
    }
    read = PairParams.from_record(old)
    assert (read.splat, read.label_rule, read.surface_probe) == ("fixed", "nearest", 0.0)
    assert PairParams.from_record(now.to_dict()) == now
    # another sampler's record is described, not refused (from_dict refuses it: outputs cannot be rebuilt)
    assert PairParams.from_record({**now.to_dict(), "sampler": "v0"}).views == now.views
    with pytest.raises(Exception, match="sampler"):
        PairParams.from_dict({**now.to_dict(), "sampler": "v0"})
    with pytest.raises(Exception, match="unknown"):
        PairParams.from_record({"no_such_knob": 1})


def test_release_params_refuse_a_pad_that_is_not_a_bool() -> None:
    from siteline.records.params.release import ReleaseParams

    assert ReleaseParams.from_dict(ReleaseParams().to_dict()) == ReleaseParams()
    with pytest.raises(ReleaseError, match="pad"):
        ReleaseParams.from_dict({"pad": "yes"})
