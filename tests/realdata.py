"""The real public clouds under tests/data/real (README there) and later epochs made from them: the
same real points with a known change planted (a block removed, a structure built), optionally moved
by a rigid offset, written in the file's own CRS and format so ingest meets them as delivered."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import laspy
import numpy as np

REAL = Path(__file__).parent / "data" / "real"
AUTZEN = REAL / "autzen_trim.laz"  # RGB, feet Lambert CRS (WKT), ASPRS 1/2, GPS week seconds
TOPOGRAPHY = REAL / "topography.laz"  # no RGB, MTM zone 7, ASPRS 1/2/9, adjusted-standard GPS time


def centre_xy(path: Path) -> np.ndarray:
    """The centre of a file's bounding box, in its CRS units."""
    with laspy.open(path) as f:
        return (np.asarray(f.header.mins[:2]) + np.asarray(f.header.maxs[:2])) / 2.0


def later_epoch(
    src: Path,
    out: Path,
    *,
    removed_box: tuple[float, float, float, float] | None = None,
    built_box: tuple[float, float, float, float, float] | None = None,
    shift: tuple[float, float, float] = (0.0, 0.0, 0.0),
    days: int = 30,
    seed: int = 0,
    reclass: dict[int, int] | None = None,
) -> Path:
    """Write ``out``: the points of ``src`` less those in ``removed_box`` (xmin, ymin, xmax, ymax in
    the file's units), plus a box structure ``built_box`` (xmin, ymin, xmax, ymax, height) whose roof
    and walls are sampled at the cloud's density from points of the file's own class 6 (building),
    all moved by ``shift`` (file units), GPS times and the creation date ``days`` later, and class
    codes mapped by ``reclass`` (another vendor's scheme)."""
    las = laspy.read(src)
    xyz = np.c_[las.x, las.y, las.z]
    keep = np.ones(len(xyz), bool)
    if removed_box is not None:
        x0, y0, x1, y1 = removed_box
        keep &= ~((xyz[:, 0] >= x0) & (xyz[:, 0] <= x1) & (xyz[:, 1] >= y0) & (xyz[:, 1] <= y1))
    points = las.points[keep]
    new = laspy.LasData(las.header)
    new.points = points
    if built_box is not None:
        new = _with_structure(new, xyz[keep], built_box, seed)
    if reclass:
        codes = np.asarray(new.classification).copy()
        for old, code in reclass.items():
            codes[np.asarray(new.classification) == old] = code
        new.classification = codes
    new.x = np.asarray(new.x) + shift[0]
    new.y = np.asarray(new.y) + shift[1]
    new.z = np.asarray(new.z) + shift[2]
    if "gps_time" in new.point_format.dimension_names:
        new.gps_time = np.asarray(new.gps_time) + days * 86_400.0
    day = las.header.creation_date or dt.date(2020, 1, 1)
    new.header.creation_date = day + dt.timedelta(days=days)
    new.update_header()
    new.write(out)
    return out


def _with_structure(las: laspy.LasData, xyz: np.ndarray, box: tuple[float, ...], seed: int) -> laspy.LasData:
    x0, y0, x1, y1, height = box
    inside = (xyz[:, 0] >= x0) & (xyz[:, 0] <= x1) & (xyz[:, 1] >= y0) & (xyz[:, 1] <= y1)
    base = float(np.percentile(xyz[inside, 2], 10)) if inside.any() else float(np.median(xyz[:, 2]))
    area = (x1 - x0) * (y1 - y0)
    span = np.ptp(xyz[:, :2], axis=0)
    density = len(xyz) / max(float(span[0] * span[1]), 1.0)
    rng = np.random.default_rng(seed)
    n_roof = max(int(density * area), 50)
    roof = np.c_[rng.uniform(x0, x1, n_roof), rng.uniform(y0, y1, n_roof), np.full(n_roof, base + height)]
    n_wall = max(int(density * 2 * (x1 - x0 + y1 - y0) * height / 4), 20)
    t = rng.uniform(0, 2 * (x1 - x0 + y1 - y0), n_wall)
    wx = np.where(
        t < x1 - x0,
        x0 + t,
        np.where(
            t < x1 - x0 + y1 - y0,
            x1,
            np.where(t < 2 * (x1 - x0) + y1 - y0, x1 - (t - (x1 - x0 + y1 - y0)), x0),
        ),
    )
    wy = np.where(
        t < x1 - x0,
        y0,
        np.where(
            t < x1 - x0 + y1 - y0,
            y0 + (t - (x1 - x0)),
            np.where(t < 2 * (x1 - x0) + y1 - y0, y1, y1 - (t - 2 * (x1 - x0) - (y1 - y0))),
        ),
    )
    wall = np.c_[wx, wy, base + rng.uniform(0, height, n_wall)]
    add = np.r_[roof, wall]
    extra = laspy.ScaleAwarePointRecord.zeros(len(add), header=las.header)
    template = las.points[:1]
    for name in las.point_format.dimension_names:
        if name not in ("X", "Y", "Z"):
            extra[name] = np.repeat(np.asarray(template[name]), len(add))
    extra.x, extra.y, extra.z = add[:, 0], add[:, 1], add[:, 2]
    extra["classification"] = np.full(len(add), 6, np.uint8)
    out = laspy.LasData(las.header)
    out.points = laspy.ScaleAwarePointRecord(
        np.concatenate([las.points.array, extra.array]),
        las.header.point_format,
        las.header.scales,
        las.header.offsets,
    )
    return out
