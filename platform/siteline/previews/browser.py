"""The release browser: one self-contained HTML page (``static/browser.html``, the items inline) that
shows a release's items in a lazily drawn grid with filters, and each item's A and B side by side or
under a swipe with its mask over either. The same page is served by the preview server for a
published release (``/browse/<name>/<version>/``) and written as a file beside a release, draft or
published, whose images it loads by relative paths (``siteline release browse``)."""

from __future__ import annotations

import html
import json
import math
import os
from collections.abc import Mapping
from importlib.resources import files
from pathlib import Path

import numpy as np

from siteline.errors import ReleaseError
from siteline.records.release import Manifest
from siteline.release.manifest import read_manifest
from siteline.schema import JSON, json_number, json_object
from siteline.stores import atomic_file

COLUMNS = (
    "id", "split", "pair", "view", "strategy", "coverage", "valid", "change_ratio", "filled", "size", "padded",
    "ignore", "camera", "change_visible",
)  # fmt: skip


def camera_figures(camera: Mapping[str, JSON]) -> dict[str, JSON]:
    """What a person reads of a synthetic camera (``schema/camera.schema.json``): its centre in
    site-local metres, heading (degrees clockwise from site north, +y), down-tilt (degrees below the
    horizon, 90 = nadir), focal length (pixels) and horizontal field of view (degrees)."""
    pose = json_object(camera["cam_from_world"], "cam_from_world")
    r = np.asarray(pose["rotation"], dtype=np.float64)
    t = np.asarray(pose["translation"], dtype=np.float64)
    centre = -r.T @ t
    axis = r[2]  # the optical axis (camera +z) in the site frame
    heading = math.degrees(math.atan2(axis[0], axis[1])) % 360.0
    tilt = math.degrees(math.asin(max(-1.0, min(1.0, -axis[2]))))
    width, fx = json_number(camera["width"], "width"), json_number(camera["fx"], "fx")
    hfov = math.degrees(2 * math.atan(width / (2 * fx)))
    return {
        "centre": [round(float(v), 4) for v in centre],
        "heading": round(heading, 2),
        "tilt": round(tilt, 2),
        "fx": round(float(fx), 3),
        "hfov": round(hfov, 2),
    }


def browser_data(doc: Manifest, images: str, viewer: str | None) -> dict[str, JSON]:
    """The page's data: the items as rows of :data:`COLUMNS` (compact: 5,000 items are ~1.5 MB),
    where the images are (``images``: a URL or a path relative to the page, the release's root) and
    the 3D viewer's base URL for the release's pairs (None where no server is behind the page)."""
    rows: list[JSON] = []
    for it in sorted(doc.items, key=lambda it: it.id):
        cam = it.camera
        rows.append([
            it.id, it.split, it.pair, it.view, it.strategy, round(it.coverage, 5),
            round(it.valid, 5), round(it.change_ratio, 5), round(it.filled, 5),
            it.size_px, it.padded_px,
            {k: round(v, 5) for k, v in it.ignore.items()}, camera_figures(cam) if cam else None,
            round(it.change_visible, 5) if it.change_visible is not None else None,
        ])  # fmt: skip
    return {
        "name": doc.name, "version": doc.version, "images": images.rstrip("/"), "viewer": viewer,
        "columns": list(COLUMNS), "rows": rows,
    }  # fmt: skip


def browser_page(doc: Manifest, images: str, viewer: str | None = None, status: str = "published") -> str:
    """The release browser of manifest ``doc`` as one HTML page (:func:`browser_data`)."""
    template = files("siteline.previews").joinpath("static/browser.html").read_text()
    data = json.dumps(browser_data(doc, images, viewer), separators=(",", ":"))
    title = f"{doc.title} ({status}): {len(doc.items)} items"
    # inside <script>: no '</' may end the element early
    return template.replace("{{TITLE}}", html.escape(title)).replace("{{DATA}}", data.replace("</", "<\\/"))


def default_page_path(root: Path) -> Path:
    """Where ``siteline release browse`` writes a release's page by default: beside the release's
    folder, never inside it (``<releases>/<name>/<version>.html``; a draft's beside the draft)."""
    return root.parent / f"{root.name}.html"


def write_browser(
    root: Path, out: Path | None = None, status: str = "published", replace: bool = True
) -> Path:
    """Write the browser of the release at ``root`` to the HTML file ``out`` (default
    :func:`default_page_path`; a folder: ``<name>-<version>.html`` in it), its images addressed
    relative to ``out``'s folder so the page opens from the disk (file://) or wherever the two are
    served together. Written whole (a temporary file renamed into place, siteline.stores.atomic_file).
    :class:`ReleaseError` when ``out`` lies inside the release, when it exists and ``replace`` is
    False, or when it is not a regular file (a FIFO, a device, a socket: never replaced)."""
    root = Path(root).resolve()
    out = Path(out).absolute() if out is not None else default_page_path(root)
    if Path(os.path.realpath(out)).is_relative_to(root):
        raise ReleaseError(
            f"{out} is inside the release {root}: a release is never written into; choose a path beside it."
        )
    if out.is_dir():
        out = out / f"{root.parent.name}-{root.name}.html"
    if os.path.lexists(out) and not (out.is_file() and not out.is_symlink()):
        raise ReleaseError(f"{out} exists and is not a regular file: give another --out.")
    if out.exists() and not replace:
        raise ReleaseError(f"{out} exists: pass --force to replace it, or give another --out.")
    doc = read_manifest(root)
    images = Path(os.path.relpath(root, out.parent)).as_posix()
    page = browser_page(doc, images, None, status)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(out) as tmp:
        tmp.write_text(page)
    return out
