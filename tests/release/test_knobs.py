"""Release settings: layers (defaults, site, command), auto scale and point size from the site's
cameras and density, the image-size floor, and their validation."""

from __future__ import annotations

import math

import pytest

from siteline.errors import ReleaseError
from siteline.records.params.presets import PRESETS
from siteline.records.params.release import ReleaseKnobs
from siteline.records.release import CameraView, SiteSurvey
from siteline.release.knobs import auto_point_size, auto_scale, check_image_size, resolve

# the synthetic site's photos: 660 x 495, fx 440, 60 m above the ground
SYNTH = SiteSurvey((CameraView(1, 660, 495, 440.0, 60.0), CameraView(2, 660, 495, 440.0, 64.0)), 10.0)
# the paper's: 5645 x 4082 undistorted, ~84 degree field of view, 80 m up, 6000 points/m2
PAPER = SiteSurvey((CameraView(1, 5645, 4082, 3135.0, 80.0),), 6000.0)


def test_auto_scale_gives_the_smallest_camera_a_512_px_long_side() -> None:
    scale, why = auto_scale(SYNTH)
    assert scale == 0.78 and math.floor(660 * scale + 0.5) >= 512 and "660 x 495" in why
    assert auto_scale(PAPER)[0] == 0.10  # 565 px: the paper's regime
    mixed = SiteSurvey((*SYNTH.cameras, CameraView(3, 400, 300, 300.0, 60.0)), 10.0)
    assert auto_scale(mixed)[0] == 1.28  # the smallest camera decides (scene 3)
    with pytest.raises(ReleaseError, match="no registered camera"):
        auto_scale(SiteSurvey((), None))


def test_auto_point_size_covers_the_gap_between_points() -> None:
    size, why = auto_point_size(SYNTH, 0.78)
    spacing_px = (1 / math.sqrt(10.0)) * 440.0 * 0.78 / 60.0  # the upper median of two cameras: the lower one
    assert size == 3 and size >= math.sqrt(2) * spacing_px and size - 2 < math.sqrt(2) * spacing_px
    assert "points/m2" in why
    assert auto_point_size(PAPER, 0.1)[0] == 1  # dense scans: one pixel a point
    sparse = SiteSurvey(SYNTH.cameras, 1.0)
    assert auto_point_size(sparse, 0.78)[0] == 9  # 5.7 px spacing: a 9 px disk
    assert auto_point_size(SiteSurvey(SYNTH.cameras, 0.001), 4.0)[0] == 15  # capped at the renderer's most


def test_layers_apply_preset_then_knobs_site_then_command() -> None:
    site = ReleaseKnobs(preset="balanced", pair={"views": 40, "point_size_px": 5})
    command = ReleaseKnobs(pair={"seed": 3})
    p = resolve([site, command], SYNTH)
    assert (p.pair.scale, p.pair.point_size_px, p.pair.views, p.pair.seed) == (0.25, 5, 40, 3)
    assert p.pair.lod_factor == PRESETS["balanced"]["lod_factor"] and p.preset == "balanced"
    assert p.derived == {}  # nothing was left auto
    # a command's preset wins over the site's knobs for what it sets; 'auto' undoes a layer below
    p = resolve([site, ReleaseKnobs(preset="exact", pair={"scale": "auto"})], SYNTH)
    assert (p.pair.scale, p.pair.point_size_px, p.preset) == (0.78, 3, "exact")
    assert set(p.derived) == {"scale"}
    p = resolve([ReleaseKnobs(), ReleaseKnobs()], SYNTH)  # nothing set: both auto, defaults elsewhere
    assert (p.pair.scale, p.pair.point_size_px, p.pair.views, p.min_image_px, p.pad) == (
        0.78,
        3,
        300,
        256,
        True,
    )
    assert resolve([ReleaseKnobs(pad=False, min_image_px=64)], SYNTH).min_image_px == 64
    # the radius ceiling: 1 m unless a layer sets it, in the parameters' JSON only when set
    assert p.radius_ceiling_m == 1.0 and "radius_ceiling_m" not in p.to_dict()
    q = resolve([ReleaseKnobs(radius_ceiling_m=0.3), ReleaseKnobs(pair={"change_rule": "geometry"})], SYNTH)
    assert (
        q.radius_ceiling_m == 0.3
        and q.to_dict()["radius_ceiling_m"] == 0.3
        and q.pair.change_rule == "geometry"
    )
    assert type(q).from_dict(q.to_dict()) == q


def test_images_under_the_floor_are_refused_with_the_scale_that_would_do() -> None:
    fast = resolve([ReleaseKnobs(preset="fast")], SYNTH)
    with pytest.raises(
        ReleaseError, match=r"83 x 62 px \(scale 0.125 of scene 1's 660 x 495 px cameras\).*--scale 0.39"
    ):
        check_image_size(fast, SYNTH, "release r")
    check_image_size(resolve([ReleaseKnobs(preset="fast", min_image_px=64)], SYNTH), SYNTH, "release r")
    check_image_size(resolve([ReleaseKnobs(preset="fast")], PAPER), PAPER, "release r")  # 706 px: fine
    check_image_size(resolve([ReleaseKnobs(pair={"scale": 0.39})], SYNTH), SYNTH, "release r")  # 257 px


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"pair": {"views": 0}}, "views"),
        ({"pair": {"scale": "big"}}, "scale"),
        ({"pair": {"lod_factor": "auto"}}, "may be 'auto'"),
        ({"pair": {"hue": 1}}, "unknown knob"),
        ({"preset": "turbo"}, "unknown preset"),
        ({"min_image_px": 0}, "min_image_px"),
        ({"pad": "yes"}, "pad"),
        ({"speed": 1}, "unknown key"),
        ({"radius_ceiling_m": 0}, "radius_ceiling_m"),
        ({"radius_ceiling_m": "1m"}, "radius_ceiling_m"),
        ({"pair": {"change_rule": "classes"}}, "change rule 'classes'"),
    ],
)
def test_bad_settings_are_refused_by_name(doc, message) -> None:
    with pytest.raises(ReleaseError, match=message):
        ReleaseKnobs.from_dict(doc)


def test_update_writes_over_and_unsets() -> None:
    stored = ReleaseKnobs(preset="fast", pair={"views": 40, "scale": 0.5}, min_image_px=128)
    new = stored.updated(
        ReleaseKnobs(pair={"views": 60}, radius_ceiling_m=0.2), unset=["scale", "min_image_px"]
    )
    assert new.to_dict() == {"preset": "fast", "pair": {"views": 60}, "radius_ceiling_m": 0.2}
    assert "radius_ceiling_m" not in new.updated(ReleaseKnobs(), unset=["radius_ceiling_m"]).to_dict()
    assert ReleaseKnobs.from_dict(new.to_dict()) == new
    with pytest.raises(ReleaseError, match="not a release setting"):
        stored.updated(ReleaseKnobs(), unset=["hue"])
