"""The site fence: a simple polygon in site-local metres (DESIGN.md §1, §4).

Points outside the fence become class ``ignore``; mirror views reflect across its segments.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt
import shapely
from shapely.validation import explain_validity

from siteline.errors import GeometryError
from siteline.tolerances import LENGTH_TOL_M

# A fence vertex further than this from the site origin means the file is in another frame or unit.
MAX_FENCE_EXTENT_M = 50_000.0


def validate_fence(vertices_m: npt.ArrayLike, source: str = "fence") -> list[tuple[float, float]]:
    """Check a closed ring of (x, y) site-local metres; return it without the repeated last vertex.

    Raises :class:`GeometryError` naming ``source`` when the ring is not closed, has fewer than three
    distinct vertices, is not finite, has no area, or intersects itself.
    """
    pts = np.asarray(vertices_m, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise GeometryError(f"{source}: fence vertices must be (x, y) pairs, got shape {pts.shape}.")
    if not np.isfinite(pts).all():
        raise GeometryError(f"{source}: fence has a non-finite vertex.")
    if len(pts) < 4 or not np.array_equal(pts[0], pts[-1]):
        raise GeometryError(
            f"{source}: fence polygon is not closed: its last vertex must repeat the first "
            f"(got {len(pts)} vertices, first {pts[0].tolist() if len(pts) else None}, last "
            f"{pts[-1].tolist() if len(pts) else None})."
        )
    ring = pts[:-1]
    if len(np.unique(ring, axis=0)) < 3:
        raise GeometryError(f"{source}: fence needs at least 3 distinct vertices.")
    if np.abs(ring).max() > MAX_FENCE_EXTENT_M:
        raise GeometryError(
            f"{source}: fence reaches {np.abs(ring).max():.0f} m from the site origin; fence coordinates "
            "must be in the site CRS near the origin (is the origin right?)."
        )
    poly = shapely.Polygon(ring)
    if not poly.is_valid:
        raise GeometryError(
            f"{source}: fence polygon is invalid ({explain_validity(poly)}): it must not intersect itself."
        )
    if poly.area <= 0.0:
        raise GeometryError(f"{source}: fence polygon has no area.")
    return [(float(x), float(y)) for x, y in ring]


def load_fence_geojson(path: Path, origin: Sequence[float]) -> list[tuple[float, float]]:
    """Read a fence from a GeoJSON file in the site CRS and return it in site-local metres.

    The file holds one Polygon (a Feature, FeatureCollection of one feature, or bare geometry) whose
    coordinates are easting/northing in the site CRS, as a survey export gives them; the site origin
    (float64) is subtracted.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise GeometryError(f"fence file {path} does not exist.") from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise GeometryError(f"fence file {path} is not valid GeoJSON: {exc}") from exc
    geom = doc
    if isinstance(doc, dict) and doc.get("type") == "FeatureCollection":
        feats = doc.get("features") or []
        if len(feats) != 1:
            raise GeometryError(f"fence file {path}: expected exactly one feature, found {len(feats)}.")
        geom = feats[0].get("geometry")
    elif isinstance(doc, dict) and doc.get("type") == "Feature":
        geom = doc.get("geometry")
    if not isinstance(geom, dict) or geom.get("type") != "Polygon":
        raise GeometryError(
            f"fence file {path}: expected a GeoJSON Polygon, found {getattr(geom, 'get', lambda _: None)('type')!r}."
        )
    rings = geom.get("coordinates")
    if not isinstance(rings, list):
        raise GeometryError(
            f"fence file {path}: the Polygon's coordinates must be a list of rings of [x, y] pairs, got {rings!r}."
        )
    if len(rings) != 1:
        raise GeometryError(
            f"fence file {path}: the fence must be one ring without holes, found {len(rings)} rings."
        )
    if not isinstance(rings[0], list) or not rings[0]:
        raise GeometryError(f"fence file {path}: the fence ring has no vertices.")
    try:
        ring = np.asarray([[float(c[0]), float(c[1])] for c in rings[0]], dtype=np.float64).reshape(-1, 2)
    except (TypeError, ValueError, IndexError) as exc:
        raise GeometryError(f"fence file {path}: a coordinate is not a number pair.") from exc
    local = ring - np.asarray(origin[:2], dtype=np.float64)
    return validate_fence(local, source=f"fence file {path}")


def fence_geojson(vertices_m: Sequence[Sequence[float]], origin: Sequence[float]) -> dict:
    """GeoJSON Polygon (site CRS coordinates) of a site-local fence ring."""
    ring = [[float(x) + origin[0], float(y) + origin[1]] for x, y in vertices_m]
    ring.append(ring[0])
    return {"type": "Polygon", "coordinates": [ring]}


def inside_fence(
    xy_m: np.ndarray,
    vertices_m: Sequence[Sequence[float]],
    tol_m: float = LENGTH_TOL_M,
    box: Sequence[float] | None = None,
) -> np.ndarray:
    """Which points lie inside the fence, or within ``tol_m`` of it (on the fence counts as inside,
    at every coordinate magnitude: siteline.tolerances). xy_m: (N, 2+) site-local metres.
    Returns (N,) bool. Points whose bounding box (``box``: (xmin, ymin, xmax, ymax) when the caller
    knows it) the fence covers are inside without a test each."""
    poly = shapely.Polygon(vertices_m)
    xy = np.asarray(xy_m, dtype=np.float64)
    if len(xy):
        lo, hi = (box[:2], box[2:]) if box is not None else (xy[:, :2].min(axis=0), xy[:, :2].max(axis=0))
        if shapely.covers(poly, shapely.box(*lo, *hi)):
            return np.ones(len(xy), dtype=bool)
    inside = shapely.intersects_xy(poly, xy[:, 0], xy[:, 1])
    out = ~inside
    if tol_m > 0 and out.any():
        near = shapely.distance(poly.exterior, shapely.points(xy[out, 0], xy[out, 1])) <= tol_m
        inside[np.flatnonzero(out)[near]] = True
    return inside


def fence_area_m2(vertices_m: Sequence[Sequence[float]]) -> float:
    """Area enclosed by the fence in m2."""
    return float(shapely.Polygon(vertices_m).area)


def nearest_segment(
    point_xy: npt.ArrayLike, vertices_m: Sequence[Sequence[float]]
) -> tuple[np.ndarray, np.ndarray]:
    """The fence segment (a, b), each (2,) float64 metres, nearest to ``point_xy``."""
    ring = np.asarray(vertices_m, dtype=np.float64)
    a = ring
    b = np.roll(ring, -1, axis=0)
    p = np.asarray(point_xy, dtype=np.float64)[:2]
    ab = b - a
    t = np.clip(((p - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-300), 0.0, 1.0)
    d = np.linalg.norm(a + t[:, None] * ab - p, axis=1)
    i = int(np.argmin(d))
    return a[i], b[i]


def is_finite_ring(vertices_m: Sequence[Sequence[float]]) -> bool:
    return all(math.isfinite(c) for v in vertices_m for c in v)


# a scene's outline: concave hull of its sample (shapely's ratio: 0 most concave, 1 convex), simplified
FOOTPRINT_RATIO = 0.2
FOOTPRINT_SIMPLIFY_M = 2.0


def footprint(sample_xy: np.ndarray) -> list[tuple[float, float]] | None:
    """The outline of a scene's (N, 2+) site-local sample: a concave hull, simplified and snapped to
    the centimetre, as a fence ring (no closing vertex); None when the points span no area."""
    xy = np.unique(np.round(np.asarray(sample_xy, dtype=np.float64)[:, :2], 2), axis=0)
    if len(xy) < 3:
        return None
    hull = shapely.concave_hull(shapely.multipoints(xy), ratio=FOOTPRINT_RATIO)
    if isinstance(hull, shapely.MultiPolygon):
        hull = max(hull.geoms, key=lambda g: g.area)
    if not isinstance(hull, shapely.Polygon) or hull.area <= 0.0:
        return None
    simple = hull.simplify(FOOTPRINT_SIMPLIFY_M, preserve_topology=True)
    ring = np.round(np.asarray(shapely.get_coordinates(shapely.Polygon(simple.exterior)))[:, :2], 2)
    try:
        return validate_fence(ring, source="scene footprint")  # shapely's exterior ring is closed
    except GeometryError:  # a degenerate outline: no footprint rather than a wrong one
        return None
