"""A pair's change rule from its scenes' class schemes (siteline.labels.rule), and the scheme a LAS
file's codes look like (siteline.site.taxonomy.detect_scheme), on the real fixtures' codes."""

from __future__ import annotations

import numpy as np
import pytest

from siteline.errors import PairError
from siteline.labels.change import change_flags
from siteline.labels.rule import resolve_change_rule, scheme_differences
from siteline.records.pairs import ChangeRulePlan
from siteline.site.taxonomy import default_taxonomy, detect_scheme

TAX = default_taxonomy()
# scene 1 separates vegetation; scene 2's vendor classified the same low vegetation as ground
VEG = {"ground": 6_000, "vegetation": 3_000, "building": 1_000}
NO_VEG = {"ground": 9_000, "building": 1_000}


def test_a_class_present_in_one_scene_and_absent_in_the_other_is_stated() -> None:
    diff = scheme_differences((1, VEG), (2, NO_VEG), TAX)
    assert diff == ("vegetation is 30.0% of scene 1's kept points and 0.00% of scene 2's",)
    assert scheme_differences((1, VEG), (2, VEG | {"crane": 500}), TAX) == ()  # a crane is real change
    # ignored classes do not count towards the shares
    assert scheme_differences((1, VEG | {"ignore": 10**6}), (2, VEG), TAX) == ()
    assert scheme_differences((1, {}), (2, VEG), TAX) == ()


def test_auto_takes_geometry_only_when_schemes_differ_and_an_explicit_rule_is_kept() -> None:
    auto = resolve_change_rule("auto", (1, VEG), (2, NO_VEG), TAX)
    assert auto.rule == "geometry" and "classify differently" in auto.why and auto.differences
    same = resolve_change_rule("auto", (1, VEG), (2, VEG), TAX)
    assert same.rule == "semantic" and not same.differences
    asked = resolve_change_rule("semantic", (1, VEG), (2, NO_VEG), TAX)
    assert asked.rule == "semantic" and asked.why == "asked for" and asked.differences == auto.differences
    with pytest.raises(PairError, match="change rule 'colour'"):
        resolve_change_rule("colour", (1, VEG), (2, VEG), TAX)
    assert ChangeRulePlan.from_dict(auto.to_dict()) == auto
    assert ChangeRulePlan.from_dict(None).rule == "semantic"


def test_geometry_rule_flags_only_what_moved() -> None:
    """The same surface classified vegetation in A and ground in B: the semantic rule flags all of
    it; the geometry rule flags only the points with nothing within the radius (the 10 m block)."""
    rng = np.random.default_rng(0)
    xyz = np.c_[rng.uniform(0, 20, (4000, 2)), np.zeros(4000)]
    a_cls = np.where(xyz[:, 0] < 10, TAX.id_of("vegetation"), TAX.id_of("ground")).astype(np.uint8)
    b_xyz = xyz.copy()
    b_xyz[xyz[:, 1] > 18, 2] += 5.0  # a real change: this strip rose 5 m
    b_cls = np.full(4000, TAX.id_of("ground"), np.uint8)
    ignored = TAX.ignored_lut()
    semantic, geometry = (
        change_flags(
            xyz, a_cls, b_xyz, b_cls, 0.5, ignored, geometric=ChangeRulePlan(rule).geometric_lut(TAX)
        )
        for rule in ("semantic", "geometry")
    )
    assert (semantic[xyz[:, 0] < 10] == 1).all()
    # a point of the strip more than the radius from its edge has nothing near: changed
    assert (geometry[xyz[:, 1] > 18.5] == 1).all() and (geometry[xyz[:, 1] < 18] == 0).all()


@pytest.mark.parametrize(
    ("codes", "scheme"),
    [
        ({1: 83_893, 2: 26_107}, "asprs"),  # autzen_trim.laz
        ({1: 61_347, 2: 8_159, 9: 3_897}, "asprs"),  # topography.laz
        ({0: 10, 1: 5}, "unclassified"),
        ({2: 10, 19: 3, 25: 4}, "asprs+site"),  # the default taxonomy's construction codes
        ({2: 10, 64: 3}, "custom"),
        ({}, "empty"),
    ],
)
def test_scheme_is_read_from_the_codes(codes, scheme) -> None:
    assert detect_scheme(codes, TAX) == scheme
