"""Writing a render to disk: rgb.png, hit.png, depth.npy, stats.json."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PIL import Image

from siteline.render.zbuffer import RenderResult
from siteline.schema import JSON
from siteline.stores import write_file


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` whole (siteline.stores.write_file)."""
    write_file(Path(path), lambda fh: fh.write(data))


def png_bytes(image: np.ndarray) -> bytes:
    """PNG encoding of an (H, W) or (H, W, 3) uint8/bool image (deterministic bytes)."""
    import io

    arr = image.astype(np.uint8) * 255 if image.dtype == bool else image
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(arr)).save(buf, format="PNG", optimize=False, compress_level=6)
    return buf.getvalue()


def write_render(
    result: RenderResult, out_dir: Path, extra_stats: dict[str, JSON] | None = None
) -> dict[str, Path]:
    """Write ``rgb.png`` (black where no hit; see hit.png), ``hit.png`` (white = hit), ``depth.npy``
    (float32 metres, NaN where no hit) and ``stats.json`` into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"hit": out / "hit.png", "depth": out / "depth.npy", "stats": out / "stats.json"}
    if "rgb" in result.attributes:
        paths["rgb"] = out / "rgb.png"
        atomic_write_bytes(paths["rgb"], png_bytes(result.rgb))
    atomic_write_bytes(paths["hit"], png_bytes(result.hit))
    import io

    buf = io.BytesIO()
    np.save(buf, result.depth)
    atomic_write_bytes(paths["depth"], buf.getvalue())
    stats: dict[str, JSON] = dict(result.stats)
    stats.update(extra_stats or {})
    stats["camera"] = result.camera.to_dict()
    atomic_write_bytes(paths["stats"], (json.dumps(stats, indent=2) + "\n").encode())
    return paths
