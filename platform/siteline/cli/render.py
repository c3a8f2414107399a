"""``siteline render`` and ``siteline views generate``: render a LAS/LAZ file, generate synthetic views."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import typer

from siteline.camera.pinhole import Camera
from siteline.cli.common import JsonOption, emit, print_record, progress_bars
from siteline.errors import CameraError, SchemaError
from siteline.schema import load_json
from siteline.site.fence import load_fence_geojson
from siteline.site.taxonomy import default_taxonomy, load_taxonomy

if TYPE_CHECKING:
    from siteline.views.generate import NamedCamera

views_app = typer.Typer(
    help="Synthetic viewpoints (vertical, mirror, forward sampling).", no_args_is_help=True
)

OriginOption = typer.Option(
    (0.0, 0.0, 0.0),
    "--origin",
    help="Site origin X Y Z in the cloud's CRS; cameras are in the site-local frame of it.",
)


def _camera_file(path: Path) -> list[NamedCamera]:
    from siteline.views.generate import NamedCamera

    doc = load_json(path, "camera")
    items = doc.get("cameras", doc) if isinstance(doc, dict) else doc
    if isinstance(items, dict):
        items = [items]
    if not isinstance(items, list) or not items:
        raise SchemaError(
            f"camera file {path} holds no camera (a camera object, a list, or {{'cameras': [...]}})."
        )
    out = []
    for i, item in enumerate(items):
        try:
            cam = Camera.from_dict(item, source=f"camera file {path} entry {i}")
        except CameraError as exc:
            raise CameraError(f"camera file {path} entry {i}: {exc}") from exc
        out.append(NamedCamera(str(item.get("name", f"camera_{i:04d}")), cam))
    return out


def render(
    input: Path = typer.Argument(..., help="LAS/LAZ point cloud."),
    camera: Path = typer.Option(
        ..., "--camera", help="Camera JSON (schema/camera.schema.json), site-local frame."
    ),
    scale: float = typer.Option(
        0.125, "--scale", help="Render scale of the camera's image size (1, 0.5, 0.25, 0.125)."
    ),
    point_size: int = typer.Option(
        1, "--point-size", help="Point size in pixels: 1, or an odd disk diameter (3)."
    ),
    out: Path = typer.Option(..., "--out", help="Output folder: rgb.png, hit.png, depth.npy, stats.json."),
    origin: tuple[float, float, float] = OriginOption,
    device: str = typer.Option("cpu", "--device", help="torch device: cpu or cuda."),
    precision: str = typer.Option(
        "float32", "--precision", help="Projection arithmetic: float32 or float64."
    ),
    as_json: bool = JsonOption,
) -> None:
    """Render a point cloud through a camera into RGB, hit mask and depth."""
    from siteline.pointpass import read_site_local
    from siteline.records.params.render import RenderParams
    from siteline.render.outputs import write_render
    from siteline.render.zbuffer import render_points

    settings = RenderParams(scale=scale, point_size_px=point_size, precision=precision)
    cam = _camera_file(camera)[0].camera
    cloud = read_site_local(input, origin)
    attrs = {"rgb": cloud.rgb} if cloud.rgb is not None else {}
    result = render_points(cloud.xyz, cam, settings, attrs, device=device)
    paths = write_render(
        result, out, {"input": str(input), "settings": settings.to_dict(), "origin": list(origin)}
    )
    record: dict[str, object] = {
        k: result.stats[k]
        for k in ("points_read", "points_in_frustum", "coverage", "seconds", "width", "height")
    }
    record["out"] = str(out)
    record["files"] = {k: str(v) for k, v in paths.items()}
    emit(as_json, record, lambda: print_record(f"render of {input.name}", record))


@views_app.command("generate")
def views_generate(
    cameras: Path = typer.Option(
        ..., "--cameras", help="Real cameras JSON (list, or {'cameras': [...]}) with names."
    ),
    ground: Path = typer.Option(
        ...,
        "--ground",
        help="Classified LAS/LAZ of the scene: its ground class fits the plane, "
        "and all of it is the geometry views are checked against.",
    ),
    fence: Path | None = typer.Option(
        None, "--fence", help="Fence GeoJSON in the site CRS (mirror sampling needs it)."
    ),
    origin: tuple[float, float, float] = OriginOption,
    n: int = typer.Option(300, "--n", help="Views to keep (seeded, strategy-stratified)."),
    seed: int = typer.Option(0, "--seed", help="Sampling seed."),
    scale: float = typer.Option(0.125, "--scale", help="Render scale used for the coverage check."),
    min_coverage: float = typer.Option(
        0.5, "--min-coverage", help="Reject views covering less than this at --scale."
    ),
    point_size: int = typer.Option(
        1, "--point-size", help="Point size (odd, px) of the coverage render: the one you render with."
    ),
    taxonomy: Path | None = typer.Option(
        None, "--taxonomy", help="Taxonomy JSON mapping LAS codes (default: schema/)."
    ),
    out: Path = typer.Option(..., "--out", help="Output views JSON."),
    as_json: bool = JsonOption,
) -> None:
    """Generate synthetic views: 32 candidates per real camera, rejection, stratified sample of N."""
    from siteline.pointpass import read_site_local
    from siteline.records.params.views import ViewParams
    from siteline.views.generate import generate_views
    from siteline.views.ground import fit_ground_plane
    from siteline.views.sources import ArrayPointSource

    params = ViewParams(views=n, seed=seed, scale=scale, min_coverage=min_coverage, point_size_px=point_size)
    real = _camera_file(cameras)
    fence_m = load_fence_geojson(fence, origin) if fence is not None else None
    cloud = read_site_local(ground, origin)
    tax = load_taxonomy(taxonomy) if taxonomy else default_taxonomy()
    lut, _ = tax.code_lut("las")
    is_ground = lut[cloud.classification] == tax.id_of("ground")
    plane = fit_ground_plane(cloud.xyz[is_ground], seed=seed)
    source = ArrayPointSource(cloud.xyz)
    with progress_bars(False) as bars:
        bars("generating views", 0, len(real))
        result = generate_views(
            real, plane, fence_m, source, params, progress=lambda k: bars("generating views", k, None)
        )
    doc = result.to_dict()
    doc["origin"] = list(origin)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    summary = {
        "out": str(out),
        "real_cameras": len(real),
        "candidates": result.candidates,
        "rejected": result.rejected,
        "kept": len(result.views),
        "by_strategy": {
            k: int(v)
            for k, v in zip(*np.unique([v.strategy for v in result.views], return_counts=True), strict=True)
        },
    }
    emit(as_json, summary, lambda: print_record("views", summary))
