"""Planned flights clear the scene (issue 67): the tallest structure found in the survey sample, the
auto altitude at least its height and a clearance, a given altitude under it refused naming it."""

from __future__ import annotations

import numpy as np
import pytest

from siteline.errors import RegistrationError
from siteline.records.registration import SurveyPlan
from siteline.register.planned import auto_altitude, tallest_structure
from siteline.register.scene import planned_cameras
from siteline.site.spec import make_site_spec
from siteline.site.taxonomy import default_taxonomy

TAX = default_taxonomy()
IGN = TAX.ignored_lut()
GROUND, CRANE, BUILDING, NOISE = (TAX.id_of(n) for n in ("ground", "crane", "building", "noise"))


def _sample(rng: np.random.Generator, *parts: tuple[np.ndarray, int]) -> np.ndarray:
    """A survey sample (x, y, z, intensity, class) of flat ground over 80 x 80 m at 2.5 points/m2 and
    ``parts`` (points, class)."""
    n = int(2.5 * 80 * 80)
    ground = np.c_[rng.uniform(-40, 40, n), rng.uniform(-40, 40, n), rng.normal(0, 0.02, n)]
    rows = [np.c_[ground, np.full(n, 50.0), np.full(n, GROUND)]]
    rows += [np.c_[p, np.full(len(p), 50.0), np.full(len(p), c)] for p, c in parts]
    return np.concatenate(rows)


def _jib(rng: np.random.Generator) -> np.ndarray:
    """A 24 m x 1 m jib's top at 18 m (2.5 points/m2) and its 1.5 m mast's top."""
    jib = np.c_[rng.uniform(0, 24, 60), rng.uniform(4.5, 5.5, 60), np.full(60, 18.0)]
    mast = np.c_[rng.uniform(-0.75, 0.75, 6), rng.uniform(4.25, 5.75, 6), np.full(6, 18.0)]
    return np.concatenate([jib, mast])


def test_the_tallest_structure_is_the_jib_not_a_stray_return_or_an_ignored_class() -> None:
    rng = np.random.default_rng(1)
    noise = np.array([[10.0, -10.0, 60.0], [10.2, -10.1, 61.0]])  # a bird, classed noise
    sample = _sample(rng, (_jib(rng), CRANE), (noise, NOISE))
    s = tallest_structure(sample, IGN)
    assert s is not None and s.height_m == pytest.approx(18.0, abs=0.2) and s.class_id == CRANE
    assert 0 <= s.xy[0] <= 25 and 0 <= s.xy[1] <= 10
    # a 30 m square roof at 8 m: no ground in its middle cells, the ground is taken from around it
    roof = np.c_[rng.uniform(-35, -5, 2250), rng.uniform(-35, -5, 2250), np.full(2250, 8.0)]
    s = tallest_structure(_sample(rng, (roof, BUILDING)), IGN)
    assert s is not None and s.height_m == pytest.approx(8.0, abs=0.2) and s.class_id == BUILDING
    # nothing kept: nothing to clear
    assert tallest_structure(np.zeros((0, 5)), IGN) is None


def test_the_auto_altitude_clears_the_structure_and_the_resolution_rule_only_raises_it() -> None:
    rng = np.random.default_rng(2)
    s = tallest_structure(_sample(rng, (_jib(rng), CRANE)), IGN)
    assert s is not None
    # dense: the resolution rule asks for the 20 m floor, under the jib
    h, why = auto_altitude(SurveyPlan(), 40.0, 6400.0, (s, "crane"))
    assert h == pytest.approx(s.height_m + 15.0, abs=0.1)
    assert f"clears the {s.height_m:.1f} m crane at" in why and "by 15 m" in why and "resolution rule" in why
    assert auto_altitude(SurveyPlan(clearance_m=25.0), 40.0, 6400.0, (s, "crane"))[0] == pytest.approx(
        s.height_m + 25.0, abs=0.1
    )
    # sparse: the resolution rule asks for more, and says how far that clears the structure
    h2, why2 = auto_altitude(SurveyPlan(), 0.5, 200_000.0, (s, "crane"))
    assert h2 > s.height_m + 15.0 and f"it clears the {s.height_m:.1f} m crane" in why2
    assert auto_altitude(SurveyPlan(), 0.5, 200_000.0)[0] == h2  # as before the rule when it is higher


def test_a_given_altitude_under_the_tallest_structure_is_refused_naming_it() -> None:
    rng = np.random.default_rng(3)
    sample = _sample(rng, (_jib(rng), CRANE))
    ring = [(-40.0, -40.0), (40.0, -40.0), (40.0, 40.0), (-40.0, 40.0), (-40.0, -40.0)]
    spec = make_site_spec("s", "EPSG:32618", (445_000.0, 5_030_000.0, 80.0), ring)
    with pytest.raises(
        RegistrationError, match=r"--altitude 12 m flies under the 18\.\d m crane at .* at least 33 m"
    ):
        planned_cameras(sample, None, spec, SurveyPlan(altitude_m=12.0), 0, 2.5)
    cams, record, source = planned_cameras(sample, None, spec, SurveyPlan(altitude_m=19.0), 0, 2.5)
    assert source == "planned" and record.altitude_why == "given (--altitude)" and cams
    cams, record, _ = planned_cameras(sample, None, spec, SurveyPlan(), 0, 2.5)
    assert record.survey is not None and record.survey.altitude_m >= 33.0
    assert all(c.center[2] >= 18.0 + 15.0 - 0.5 for c in cams.values())  # over the ground at ~0 m
    assert "clears the 18" in (record.altitude_why or "")


def test_a_survey_of_before_reads_back_as_clearing_nothing_and_keeps_its_json() -> None:
    doc = SurveyPlan(altitude_m=30.0).to_dict()
    assert doc["clearance_m"] == 15.0
    del doc["clearance_m"]
    old = SurveyPlan.from_dict(doc)
    assert old.clearance_m == 0.0 and old.to_dict() == doc
    with pytest.raises(RegistrationError, match="clearance"):
        SurveyPlan(clearance_m=-1.0)
