"""The release knobs as command-line options, declared once: ``site create``, ``site update`` and
``release build`` take the same options and get a :class:`ReleaseKnobs` layer of what was given."""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from typing import Any, TypeVar

import typer

from siteline.errors import ReleaseError
from siteline.records.params.release import AUTO, ReleaseKnobs

F = TypeVar("F", bound=Callable[..., Any])


def _number(text: str, option: str, kind: type) -> Any:
    if text == AUTO:
        return AUTO
    try:
        return kind(text)
    except ValueError as exc:
        raise ReleaseError(f"{option} {text!r}: give a number or 'auto'.") from exc


_OPTIONS: dict[str, tuple[Any, Any]] = {
    # name: (annotation, typer option)
    "preset": (str | None, typer.Option(None, "--preset", help="fast, balanced or exact (docs/performance.md).")),
    "scale": (str | None, typer.Option(None, "--scale", help="Render scale of the cameras' image size, or 'auto' (512 px long side).")),
    "point_size": (str | None, typer.Option(None, "--point-size", help="Point size in pixels (odd, 1-15), or 'auto' (from density).")),
    "views": (str | None, typer.Option(None, "--views", help="Views per pair, or 'auto' (the default: up to 300, as many as the cameras give).")),
    "radius": (str | None, typer.Option(None, "--radius", help="Change radius in metres, or 'auto' (2.5 x median spacing).")),
    "seed": (int | None, typer.Option(None, "--seed", help="Seed of view sampling and splits.")),
    "min_coverage": (float | None, typer.Option(None, "--min-coverage", help="Reject views covering less of the image (default 0.5).")),
    "min_valid": (float | None, typer.Option(None, "--min-valid", help="Skip views whose probe shows fewer valid pixels, and replace rendered ones (default 0.7).")),
    "splat": (str | None, typer.Option(None, "--splat", help="How big a point is drawn: world (its spacing seen from the camera, the default) or fixed (--point-size).")),
    "splat_max": (int | None, typer.Option(None, "--splat-max", help="Largest world splat, pixels across (default 31).")),
    "fill": (int | None, typer.Option(None, "--fill", help="Fill gaps from the surface around them within this many pixels (default 2; 0: none).")),
    "splat_factor": (float | None, typer.Option(None, "--splat-factor", help="World splat diameter in point spacings (default 2): smaller draws edges nearer to where surfaces end, with more holes (docs/performance.md).")),
    "trim_edges": (bool | None, typer.Option(None, "--trim-edges/--no-trim-edges", help="Give the pixels where a world splat reaches past its surface's edge to the surface behind (the default; docs/performance.md).")),
    "change_views": (int | None, typer.Option(None, "--change-views", help="Views each changed region of 1 m2 or more is put in, where candidates show it (default 5; 0: views drawn without regard to the changes).")),
    "unsure_edges": (bool | None, typer.Option(None, "--unsure-edges/--no-unsure-edges", help="Ignore the pixels the edge trim gave to a surface whose change differs from the one that reached them (the default: a thin beam's sides; docs/performance.md).")),
    "sparse_surfaces": (bool | None, typer.Option(None, "--sparse-surfaces/--no-sparse-surfaces", help="Keep a sparse surface's changed samples whole in the labels and, with unsure edges, ignore what shows between them (the default: a pole's samples a metre apart; docs/performance.md).")),
    "label_rule": (str | None, typer.Option(None, "--label-rule", help="3D change rule: adaptive (the default: a flagged point is checked against the other scene's local surface as that scan sampled it, and a place it did not observe is ignored), surface (the same within twice the radius, for scans that sample every surface alike) or nearest (nearest neighbour alone).")),
    "min_region_points": (int | None, typer.Option(None, "--min-region", help="Changed regions of fewer points are taken back to unchanged (default 8; 1 keeps every point).")),
    "surface_probe": (float | None, typer.Option(None, "--surface-probe", help="Surface and adaptive rules: also probe points whose nearest neighbour in the other scene lies beyond this many change radii, changed when off its surface (default 0.7; 0: only points the nearest test flags; docs/performance.md).")),
    "one_side_hole": (str | None, typer.Option(None, "--one-side-hole", help="Changed on one side, a hole on the other: ignore or changed.")),
    "all_points": (bool | None, typer.Option(None, "--all-points/--lod", help="Render every point (no level of detail; slower).")),
    "lod_factor": (float | None, typer.Option(None, "--lod-factor", help="Level of detail read per view (1 = half a drawn point).")),
    "colour": (str | None, typer.Option(None, "--colour", help="What images show: auto (RGB, else intensity, else elevation), rgb, intensity or elevation.")),
    "shading": (str | None, typer.Option(None, "--shading", help="Eye-dome lighting of the images: edl, or none (auto, the default: none; bench/legible.py).")),
    "change_rule": (str | None, typer.Option(None, "--change-rule", help="auto (geometry when the scenes classify differently), semantic or geometry (class-agnostic).")),
    "pad": (bool | None, typer.Option(None, "--pad/--no-pad", help="Pad images to multiples of 32 and at least 256 px.")),
    "radius_ceiling": (float | None, typer.Option(None, "--radius-ceiling", help="Warn when a pair's change radius (the smallest change it resolves) is above this, metres (default 1).")),
    "min_image_px": (int | None, typer.Option(None, "--min-image-px", help="Refuse a build whose images' long side is under this (default 256).")),
}  # fmt: skip


def knobs_of(values: dict[str, Any]) -> ReleaseKnobs:
    """The layer of the options that were given (None: not given)."""
    pair: dict[str, Any] = {}
    if values.get("scale") is not None:
        pair["scale"] = _number(values["scale"], "--scale", float)
    if values.get("point_size") is not None:
        pair["point_size_px"] = _number(values["point_size"], "--point-size", int)
    if values.get("views") is not None:
        pair["views"] = _number(values["views"], "--views", int)
    if values.get("radius") is not None:
        radius = _number(values["radius"], "--radius", float)
        pair["radius_m"] = None if radius == AUTO else radius
    for name in (
        "seed", "min_coverage", "min_valid", "one_side_hole", "all_points", "lod_factor", "colour", "shading", "change_rule", "splat",
        "splat_factor", "trim_edges", "unsure_edges", "sparse_surfaces", "label_rule", "min_region_points", "surface_probe",
    ):  # fmt: skip
        if values.get(name) is not None:
            pair[name] = values[name]
    for name, knob in (("splat_max", "splat_max_px"), ("fill", "fill_px")):
        if values.get(name) is not None:
            pair[knob] = values[name]
    if values.get("change_views") is not None:
        pair["view_params"] = {"change_views": values["change_views"]}
    return ReleaseKnobs(
        values.get("preset"),
        pair,
        values.get("pad"),
        values.get("min_image_px"),
        values.get("radius_ceiling"),
    )


def with_knob_options(fn: F) -> F:
    """Give command ``fn`` the knob options; it receives them as one ``knobs: ReleaseKnobs``."""
    sig = inspect.signature(fn)
    params = [p for p in sig.parameters.values() if p.name != "knobs"]
    extra = [
        inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=option, annotation=annotation)
        for name, (annotation, option) in _OPTIONS.items()
    ]

    @functools.wraps(fn)
    def command(*args: Any, **kwargs: Any) -> Any:
        values = {name: kwargs.pop(name) for name in _OPTIONS}
        return fn(*args, knobs=knobs_of(values), **kwargs)

    command.__signature__ = sig.replace(parameters=[*params, *extra])  # type: ignore[attr-defined]
    return command  # type: ignore[return-value]
