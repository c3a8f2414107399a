"""Preview images of a pair's outputs: its first views as rows of t1 | t2 | coloured mask, written
once per output digest under ``SITELINE_HOME/previews`` (siteline.stores.layout.pair_previews)."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import quote

from siteline.config import Settings
from siteline.records.pairs import PairOutput
from siteline.release.build import read_png
from siteline.release.datasheet import triplet_grid
from siteline.stores import join, layout, write_file

SAMPLES = "samples.png"


def pair_samples(home: Path, out: PairOutput, count: int = 4, width: int = 960) -> Path:
    """The preview of ``out``'s first ``count`` views (``width`` pixels wide), written whole once."""
    dest = layout.pair_previews(home, out.pair_id, out.digest) / SAMPLES
    if not dest.is_file():
        triplets = [
            tuple(read_png(join(out.root, sub, v.file)) for sub in ("A", "B", "label"))
            for v in out.views[:count]
        ]
        image = triplet_grid(triplets, width)  # type: ignore[arg-type]
        write_file(dest, lambda fh: image.save(fh, format="PNG"))
    return dest


def url_of(settings: Settings, path: Path) -> str:
    """The address `siteline previews serve` gives ``path`` (a file under the home's previews or
    releases folders)."""
    rel = Path(path).resolve().relative_to(settings.home.resolve())
    return f"{settings.preview_url}/{quote(rel.as_posix())}"
