"""Persisted parameter specs: composed, validated, one name per knob, a JSON round trip."""

from __future__ import annotations

import json

import pytest

from siteline.errors import PairError, RenderError, ViewsError
from siteline.records.params.pairs import PairParams
from siteline.records.params.release import ReleaseParams
from siteline.records.params.render import RenderParams
from siteline.records.params.views import ViewParams


def test_pair_params_are_composed_of_the_stages_specs() -> None:
    p = PairParams(scale=0.5, point_size_px=3, views=6, seed=4, min_coverage=0.3, radius_m=0.2,
                   view_params={"clearance_m": 2.0})  # fmt: skip
    assert p.render_settings() == RenderParams(
        scale=0.5, point_size_px=3, splat="world", splat_max_px=31, fill_px=2, trim_edges=True,
        sparse_surfaces=True,
    )  # fmt: skip
    vp = p.view_params_spec()
    assert (vp.scale, vp.views, vp.seed, vp.min_coverage, vp.clearance_m) == (0.5, 6, 4, 0.3, 2.0)
    # the probes draw the renders' splats and judge the pair's valid share
    assert (vp.splat, vp.splat_max_px, vp.min_valid, vp.point_size_px) == ("world", 31, 0.7, 3)
    assert p.label_params().radius_m == 0.2


@pytest.mark.parametrize(
    "bad",
    [
        {"scale": 9.0},
        {"point_size_px": 2},
        {"radius_m": -1.0},
        {"views": 0},
        {"view_params": {"views": 3}},
        {"view_params": {"splat": "fixed"}},
        {"splat": "round"},
        {"fill_px": 20},
        {"view_params": {"clearance": 2.0}},
    ],
)
def test_pair_params_refuse_what_a_component_refuses(bad) -> None:
    with pytest.raises(PairError, match="pair parameters|view_params|view parameters"):
        PairParams(**bad)


def test_json_round_trips_and_unknown_keys_are_named() -> None:
    p = PairParams(scale=0.25, views=12, view_params={"mirror": False})
    assert PairParams.from_dict(json.loads(json.dumps(p.to_dict()))) == p
    r = ReleaseParams(p, "fast", pad=False)
    assert ReleaseParams.from_dict(json.loads(json.dumps(r.to_dict()))) == r
    with pytest.raises(PairError, match=r"unknown parameter\(s\) \['scael'\]"):
        PairParams.from_dict({"scael": 0.5})
    with pytest.raises(PairError, match="views=1.5 must be a int"):
        PairParams.from_dict({"views": 1.5})
    with pytest.raises(ViewsError, match="unknown parameter"):
        ViewParams.from_dict({"n_views": 3})
    with pytest.raises(RenderError, match="point_size_px='3' must be a int"):
        RenderParams.from_dict({"point_size_px": "3"})


def test_one_name_per_knob() -> None:
    shared = {"scale", "views", "seed", "min_coverage"}
    assert shared <= set(PairParams().to_dict()) and shared <= set(ViewParams().to_dict())
    assert "scale" in RenderParams().to_dict()
    assert not {"render_scale", "n_views"} & (set(ViewParams().to_dict()) | set(PairParams().to_dict()))
