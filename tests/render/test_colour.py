"""A pair's colour: RGB when both scenes carry it, else the height above the ground on the ramp, shaded
by eye-dome lighting when asked; intensity (stretched per scene) and elevation (one ramp over both) when asked;
explicit choices the data cannot give are refused naming the scene."""

from __future__ import annotations

import numpy as np
import pytest

from siteline.errors import PairError
from siteline.records.pairs import ColourPlan
from siteline.records.scan import ColourStats
from siteline.render.colour import resolve_colour

RGB = ColourStats("varies", (5.0, 200.0), (-2.0, 30.0))
NO_RGB = ColourStats("absent", (10.0, 1400.0), (0.0, 40.0))
FLAT = ColourStats("constant", None, (1.0, 20.0))


@pytest.mark.parametrize(
    ("choice", "t1", "t2", "source"),
    [
        ("auto", RGB, RGB, "rgb"),
        ("auto", None, RGB, "rgb"),  # scanned before colour was judged: its RGB, as before
        ("auto", RGB, NO_RGB, "height"),
        ("auto", NO_RGB, NO_RGB, "height"),
        ("auto", FLAT, NO_RGB, "height"),
        ("height", RGB, RGB, "height"),
        ("elevation", RGB, RGB, "elevation"),
        ("intensity", RGB, NO_RGB, "intensity"),
    ],
)
def test_resolution(choice, t1, t2, source) -> None:
    plan = resolve_colour(choice, (1, t1), (2, t2))
    assert plan.source == source and plan.why


def test_stretches_are_per_scene_for_intensity_and_shared_for_elevation() -> None:
    i = resolve_colour("intensity", (1, RGB), (2, NO_RGB))
    assert (i.stretch_t1, i.stretch_t2) == ((5.0, 200.0), (10.0, 1400.0))
    e = resolve_colour("elevation", (1, RGB), (2, NO_RGB))
    assert e.stretch_t1 == e.stretch_t2 == (-2.0, 40.0)


@pytest.mark.parametrize(
    ("choice", "words"), [("rgb", "scene 2 (constant)"), ("intensity", "scene 2"), ("hue", "use one of")]
)
def test_impossible_choices_are_refused(choice, words) -> None:
    with pytest.raises(PairError, match=words.replace("(", r"\(").replace(")", r"\)")):
        resolve_colour(choice, (1, RGB), (2, FLAT))


def test_colours_stretch_and_clip() -> None:
    xyz = np.c_[np.zeros((4, 2)), [0.0, 10.0, 20.0, 99.0]]
    grey = ColourPlan("intensity", (100.0, 200.0), (0.0, 1.0)).colours(1, xyz, np.array([50, 100, 150, 300]))
    assert grey[:, 0].tolist() == [0, 0, 128, 255] and np.array_equal(grey[:, 0], grey[:, 2])
    ramp = ColourPlan("elevation", (0.0, 20.0), (0.0, 20.0)).colours(2, xyz, None)
    assert ramp[0].tolist() == [68, 1, 84] and ramp[2].tolist() == ramp[3].tolist() == [253, 231, 37]
    rgb = np.array([[1, 2, 3]] * 4, np.uint8)
    assert ColourPlan("rgb").colours(1, xyz, rgb) is rgb


@pytest.mark.parametrize(
    ("choice", "shading", "t2", "want"),
    [("auto", "auto", RGB, "none"), ("auto", "auto", NO_RGB, "none"), ("intensity", "edl", NO_RGB, "edl"),
     ("auto", "none", NO_RGB, "none"), ("rgb", "edl", RGB, "edl")],
)  # fmt: skip
def test_shading_is_eye_dome_lighting_when_asked(choice, shading, t2, want) -> None:
    assert resolve_colour(choice, (1, RGB), (2, t2), shading=shading).shading == want


def test_height_colours_need_heights_and_use_the_ramp() -> None:
    plan = resolve_colour("auto", (1, NO_RGB), (2, NO_RGB))
    xyz = np.zeros((3, 3))
    with pytest.raises(PairError, match="heights"):
        plan.colours(1, xyz, None)
    ramp = plan.colours(1, xyz, np.array([-1.0, 0.0, 30.0]))  # below the ground and above 25 m clip
    assert ramp[0].tolist() == ramp[1].tolist() == [68, 1, 84] and ramp[2].tolist() == [253, 231, 37]


def test_eye_dome_lighting_darkens_the_far_side_of_a_depth_step_only() -> None:
    from siteline.render.shading import eye_dome

    depth = np.full((6, 8), 20.0, np.float32)
    depth[:, 4:] = 40.0  # a step: the right half lies twice as far
    depth[0, 0] = np.nan  # no point
    rgb = np.full((6, 8, 3), 200, np.uint8)
    out = eye_dome(rgb, depth)
    assert (out[:, :4] == 200).all()  # the near side and flat surfaces keep their colour
    assert (out[1:, 4] < 20).all() and (out[:, 6:] == 200).all()  # the far pixels at the step go dark
    assert np.isnan(depth[0, 0]) and out[0, 0].tolist() == [200, 200, 200]  # no point: left as drawn
