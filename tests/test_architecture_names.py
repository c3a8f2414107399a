"""Every dotted name docs/ARCHITECTURE.md gives of the library (``ingest.plan.plan_ingest``,
``siteline.schema.JSON``...) resolves: a newcomer who follows the page finds what it names."""

from __future__ import annotations

import importlib
import pkgutil
import re
from pathlib import Path

import siteline

DOC = Path(__file__).resolve().parents[1] / "docs" / "ARCHITECTURE.md"
PACKAGES = {m.name for m in pkgutil.iter_modules(siteline.__path__)} | {"siteline"}
# where the event names the page mentions (siteline.mission.uploaded...) are defined as strings
ROOT = Path(__file__).resolve().parents[1]
EVENT_SOURCES = "".join(
    p.read_text()
    for top in (Path(siteline.__file__).parent, ROOT / "flows", ROOT / "deploy")
    for p in top.rglob("*.py")
)
FILE_ENDINGS = (
    ".py",
    ".md",
    ".json",
    ".yaml",
    ".toml",
    ".zarr",
    ".png",
    ".html",
    ".js",
    ".sqlite",
    ".laz",
    ".las",
)


def _resolves(name: str) -> bool:
    parts = name.removeprefix("siteline.").split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module("siteline." + ".".join(parts[:cut]))
        except ImportError:
            continue
        try:
            for attr in parts[cut:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return False
        return True
    return False


def test_every_dotted_library_name_in_the_architecture_page_resolves() -> None:
    names = set(re.findall(r"`([A-Za-z_][\w]*(?:\.[\w]+)+)`", DOC.read_text()))
    events = {n for n in names if re.search(rf'"{re.escape(n)}"', EVENT_SOURCES)}  # event names, not code
    library = sorted(
        n for n in names - events if n.split(".")[0] in PACKAGES and not n.endswith(FILE_ENDINGS)
    )
    assert len(library) > 20  # the page names the stage entries, records and helpers
    missing = [n for n in library if not _resolves(n)]
    assert missing == [], f"docs/ARCHITECTURE.md names what does not exist: {missing}"
