"""Release settings as a site stores them and a command overrides them, and their resolution into the
:class:`ReleaseParams` a build uses: the one place a preset is applied and ``auto`` is worked out.

Layers apply in order (defaults, then the site's settings, then the command's), each its preset first
and then its own knobs, so a knob set later wins. ``scale`` and ``point_size_px`` are ``auto`` unless a
layer sets them: the scale that gives the site's smallest camera a long side of
:data:`TARGET_LONG_SIDE_PX` (the paper's 706 x 510 regime), and the smallest odd point size whose disk
covers the gap between neighbouring points at the sparsest scene's density, seen from the cameras.
A build whose images would have a long side under ``min_image_px`` (256 by default) is refused.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from siteline.errors import ReleaseError, SitelineError
from siteline.records.params.pairs import PairParams
from siteline.records.params.presets import PRESETS
from siteline.records.params.release import (
    AUTO,
    AUTO_KNOBS,
    DEFAULT_RADIUS_CEILING_M,
    ReleaseKnobs,
    ReleaseParams,
)
from siteline.records.release import SiteSurvey
from siteline.schema import json_number

# views auto: up to this many per pair, as many as the cameras and the acceptance rules give
AUTO_VIEWS = 300
TARGET_LONG_SIDE_PX = 512
MIN_IMAGE_PX = 256


def auto_scale(survey: SiteSurvey) -> tuple[float, str]:
    """The render scale (rounded up to 0.01) at which the site's smallest camera has a long side of
    at least :data:`TARGET_LONG_SIDE_PX`, and how it was chosen."""
    if not survey.cameras:
        raise ReleaseError(
            "scale is auto, but the site has no registered camera to derive it from: set it "
            "(`siteline site update SITE --scale 0.5`)."
        )
    smallest = min(survey.cameras, key=lambda c: max(c.width, c.height))
    long_side = max(smallest.width, smallest.height)
    scale = min(4.0, math.ceil(100 * TARGET_LONG_SIDE_PX / long_side - 1e-9) / 100)
    return scale, (
        f"auto: {TARGET_LONG_SIDE_PX} px long side from the smallest camera ({smallest.width} x "
        f"{smallest.height} px, scene {smallest.scene_id})"
    )


def auto_point_size(survey: SiteSurvey, scale: float) -> tuple[int, str]:
    """The smallest odd point size (1-15 px) whose disk covers the gap between neighbouring points:
    diameter >= sqrt(2) x the point spacing in pixels (spacing 1/sqrt(density) of the sparsest scene,
    seen by the median camera at ``scale`` from its height above the ground)."""
    if not survey.cameras or not survey.min_density_pts_m2:
        return 1, "auto: 1 px (no camera or density to derive it from)"
    spacing_m = 1.0 / math.sqrt(survey.min_density_pts_m2)
    per_camera = sorted(spacing_m * c.fx * scale / max(c.height_above_ground_m, 1.0) for c in survey.cameras)
    spacing_px = per_camera[len(per_camera) // 2]
    size = max(1, math.ceil(math.sqrt(2.0) * spacing_px - 1e-9))
    size = min(15, size if size % 2 else size + 1)
    return size, (
        f"auto: {size} px covers a {spacing_px:.2f} px point spacing ({spacing_m:.3f} m at "
        f"{survey.min_density_pts_m2:.4g} points/m2, median camera)"
    )


def resolve(layers: Sequence[ReleaseKnobs], survey: SiteSurvey) -> ReleaseParams:
    """The release parameters of ``layers`` (site, then command) over the defaults, with ``auto``
    worked out from ``survey``; the explanation of each derived knob is in ``derived``."""
    doc = PairParams().to_dict()
    auto, preset, pad, min_px, ceiling = set(AUTO_KNOBS), None, True, MIN_IMAGE_PX, DEFAULT_RADIUS_CEILING_M
    for layer in layers:
        if layer.preset is not None:
            doc |= PRESETS[layer.preset]
            auto -= set(PRESETS[layer.preset])
            preset = layer.preset
        for name, value in layer.pair.items():
            if value == AUTO and name in AUTO_KNOBS:
                auto.add(name)
            else:
                doc[name] = value
                auto.discard(name)
        pad = pad if layer.pad is None else layer.pad
        min_px = min_px if layer.min_image_px is None else layer.min_image_px
        ceiling = ceiling if layer.radius_ceiling_m is None else float(layer.radius_ceiling_m)
    derived: dict[str, str] = {}
    if "views" in auto:
        doc["views"] = AUTO_VIEWS
        derived["views"] = (
            f"auto: up to {AUTO_VIEWS} a pair, as many as its cameras and the acceptance rules give"
        )
    if "scale" in auto:
        doc["scale"], derived["scale"] = auto_scale(survey)
    if "point_size_px" in auto:
        doc["point_size_px"], derived["point_size_px"] = auto_point_size(
            survey, json_number(doc["scale"], "scale")
        )
    try:
        pair = PairParams.from_dict(doc)
    except SitelineError as exc:
        raise ReleaseError(f"release settings: {exc}") from exc
    return ReleaseParams(pair, preset, pad, min_image_px=min_px, derived=derived, radius_ceiling_m=ceiling)


def check_image_size(params: ReleaseParams, survey: SiteSurvey, what: str) -> None:
    """Refuse ``what`` (a release) when a camera's images would have a long side under
    ``params.min_image_px`` at ``params.pair.scale``, naming the sizes and the scale that would do."""
    if not survey.cameras:
        return
    floor = params.min_image_px
    cam = min(survey.cameras, key=lambda c: max(c.width, c.height))
    w, h = (max(1, math.floor(v * params.pair.scale + 0.5)) for v in (cam.width, cam.height))
    if max(w, h) < floor:
        need = math.ceil(100 * floor / max(cam.width, cam.height) - 1e-9) / 100
        hint = f" (preset {params.preset} is tuned for ~5645 px photos)" if params.preset else ""
        raise ReleaseError(
            f"{what}: images would be {w} x {h} px (scale {params.pair.scale:g} of scene {cam.scene_id}'s "
            f"{cam.width} x {cam.height} px cameras){hint}, under the {floor} px floor: use --scale {need:g} or "
            "more, or lower --min-image-px knowingly. Nothing was written."
        )


def disk_area_px(point_size_px: int) -> int:
    """The pixels one drawn point covers (the renderer's disk)."""
    from siteline.render.splats import disk_offsets

    return len(disk_offsets(point_size_px))


def drawn_diameter_px(spacing_px: float, pair: PairParams, point_size_px: int | None = None) -> int:
    """The disk (pixels across) a point at ``spacing_px`` from its neighbours is drawn as: the point
    size for fixed splats; for world splats its spacing times the pair's ``splat_factor``, within the
    point size and ``splat_max_px`` (siteline.render.splats)."""
    size = pair.point_size_px if point_size_px is None else point_size_px
    if pair.splat != "world":
        return size
    return int(min(pair.splat_max_px, max(size, math.ceil(pair.splat_factor * spacing_px))))


def expected_coverage(spacing_px: float, diameter_px: int) -> float:
    """The share of a surface's pixels that points at a mean spacing of ``spacing_px`` pixels, drawn as
    ``diameter_px`` disks, cover when they fall at random (1 - exp(-disk area / spacing_px**2)): a
    lower bound for scanned surfaces, which are more even than random."""
    return 1.0 - math.exp(-disk_area_px(diameter_px) / max(spacing_px, 1e-9) ** 2)


def check_coverage(params: ReleaseParams, survey: SiteSurvey, what: str) -> None:
    """Refuse ``what`` before any view is made when even the camera seeing the sparsest scene's
    points closest together (nearest pixel spacing, from its height above that scene's ground)
    would cover less than ``min_coverage`` of a surface at this scale and point size (every view
    would be rejected after minutes), naming a scale and a point size that would do."""
    pair = params.pair
    if not survey.cameras or not survey.min_density_pts_m2:
        return
    spacing_m = 1.0 / math.sqrt(survey.min_density_pts_m2)
    spacing_px = min(
        spacing_m * c.fx * pair.scale / max(c.height_above_ground_m, 1.0) for c in survey.cameras
    )
    got = expected_coverage(spacing_px, drawn_diameter_px(spacing_px, pair))
    if got >= pair.min_coverage:
        return
    sizes = [
        p
        for p in range(1, 16, 2)
        if expected_coverage(spacing_px, drawn_diameter_px(spacing_px, pair, p)) >= pair.min_coverage
    ]
    need = -math.log(1.0 - min(pair.min_coverage, 0.999))  # disk area / spacing_px**2 needed
    scale = (
        math.floor(1000 * pair.scale * math.sqrt(disk_area_px(pair.point_size_px) / need) / spacing_px) / 1000
    )
    long_side = min(max(c.width, c.height) for c in survey.cameras)
    fixes = [f"--scale {scale:g} or less"] if scale * long_side >= params.min_image_px else []
    if sizes:
        fixes.append(f"--point-size {sizes[0]}")
    raise ReleaseError(
        f"{what}: at scale {pair.scale:g} with {pair.point_size_px} px points, the sparsest scene's points "
        f"({survey.min_density_pts_m2:.3g} points/m2, {spacing_m:.2f} m apart) lie {spacing_px:.1f} px apart "
        f"even for the nearest camera, and would cover about {got:.0%} of a surface: every view would "
        f"fall under --min-coverage {pair.min_coverage:g}. Use {' or '.join(fixes + ['--scale auto --point-size auto'])}. "
        "Nothing was made."
    )
