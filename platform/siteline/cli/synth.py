"""``siteline synth site``: generate a synthetic construction site as DJI mission folders."""

from __future__ import annotations

import time
from pathlib import Path

import typer

from siteline.cli.common import JsonOption, emit, print_table, progress_bars

app = typer.Typer(help="Synthetic construction sites with ground truth.", no_args_is_help=True)


@app.command("site")
def site(
    out: Path = typer.Option(..., "--out", help="Output folder: missions/<epoch>/, truth/, fence.geojson."),
    epochs: int = typer.Option(4, "--epochs", help="Number of epochs (scenes), late November onwards."),
    density: float = typer.Option(
        10.0, "--density", help="LiDAR surface density, points per m2 (10: ~250k points per epoch)."
    ),
    seed: int = typer.Option(0, "--seed", help="Seed: the same seed gives the same bytes."),
    origin: tuple[float, float, float] = typer.Option(
        (445_000.0, 5_030_000.0, 80.0), "--origin", help="Site origin X Y Z in the CRS (ellipsoidal height)."
    ),
    crs: str = typer.Option("EPSG:32618", "--crs", help="Projected CRS of the LAS files."),
    photo_scale: float = typer.Option(
        0.125, "--photo-scale", help="Photo size as a fraction of the 5280x3956 sensor."
    ),
    snow: list[int] = typer.Option([2], "--snow-epoch", help="Epoch indices with snow (repeatable)."),
    projection_error: list[int] = typer.Option(
        [1], "--projection-error-epoch", help="Epoch indices with crane colour smeared on the ground."
    ),
    no_photos: bool = typer.Option(
        False, "--no-photos", help="LiDAR-only missions (no photos, no COLMAP model)."
    ),
    layout: str = typer.Option(
        "site",
        "--layout",
        help="site (the construction site), boxes (the analytic box scene) or slope (a sloped scene).",
    ),
    scan: str = typer.Option(
        "flown",
        "--scan",
        help="flown (an airborne scanner's first returns along flight lines that differ epoch to epoch) or sampled (every surface sampled alike, as sites were before).",
    ),
    flight_variation: float = typer.Option(
        1.0,
        "--flight-variation",
        help="How far each epoch's flight strays from the plan, in units of up to 2 degrees turned, 2.5 m shifted and 3 m higher or lower (0: every epoch flies the same lines).",
    ),
    as_json: bool = JsonOption,
) -> None:
    """Write one DJI mission folder per epoch and a ground-truth sidecar."""
    from siteline.synth import SynthParams, write_site

    cfg = SynthParams(
        epochs=epochs,
        density_pts_m2=density,
        seed=seed,
        origin=origin,
        crs=crs,
        photo_scale=photo_scale,
        snow_epochs=tuple(snow),
        projection_error_epochs=tuple(projection_error),
        photos=not no_photos,
        colmap=not no_photos,
        layout=layout,
        scan=scan,
        flight_variation=flight_variation,
    )
    t0 = time.perf_counter()
    with progress_bars(as_json) as bars:
        bars("generating epochs", 0, epochs)
        summaries = write_site(out, cfg, progress=lambda name: bars("generating epochs", 1, None))
    seconds = time.perf_counter() - t0
    records = [
        {"epoch": s.name, "time": s.time, "points": s.points, "photos": s.photos, "mission": s.mission_dir}
        for s in summaries
    ]
    emit(
        as_json,
        {"out": str(out), "seconds": seconds, "epochs": records},
        lambda: print_table(
            f"synthetic site in {out} ({seconds:.1f} s)",
            ["epoch", "time", "points", "photos", "mission"],
            [list(r.values()) for r in records],
        ),
    )
