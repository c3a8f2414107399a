"""Helpers shared by tests: an ingested synthetic site, the node-order key (imported from tests/,
which pytest puts on sys.path)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from siteline.catalog import migrate, open_catalog
from siteline.catalog.context import StageContext
from siteline.catalog.engine import make_engine
from siteline.catalog.sites import add_site
from siteline.config import Settings, sqlite_url
from siteline.pointpass import TilingResources
from siteline.site.fence import load_fence_geojson
from siteline.site.spec import make_site_spec
from siteline.synth import SynthParams

SYNTH = SynthParams(epochs=3, density_pts_m2=3.0, seed=21)


def epoch_dirs(site: Path) -> list[Path]:
    return [site / e["mission_dir"] for e in json.loads((site / "truth" / "site.json").read_text())["epochs"]]


def copy_mission(site: Path, index: int, dest: Path) -> Path:
    src = epoch_dirs(site)[index]
    out = dest / src.name
    shutil.copytree(src, out, symlinks=True)
    return out


def make_home(
    root: Path,
    url: str | None = None,
    site_dir: Path | None = None,
    name: str = "demo",
    store_url: str = "",
) -> Settings:
    home = root / "home"
    settings = Settings(
        home=home, database_url=url or sqlite_url(home / "catalog.sqlite"), store_url=store_url
    )
    engine = make_engine(settings.database_url)
    migrate.upgrade(engine)
    engine.dispose()
    cat = open_catalog(settings)
    fence = None
    if site_dir is not None:
        ring = load_fence_geojson(site_dir / "fence.geojson", SYNTH.origin)
        fence = [*ring, ring[0]]
    with cat.transaction() as s:
        add_site(s, make_site_spec(name, SYNTH.crs, SYNTH.origin, fence))
    cat.dispose()
    return settings


EXE = Path(sys.executable).with_name("siteline")


def run_exe(home: Path, *argv: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Run the installed ``siteline`` executable with ``home`` as SITELINE_HOME (and no other
    SITELINE_ setting of this process); capture its output."""
    full = {k: v for k, v in os.environ.items() if not k.startswith("SITELINE_")}
    full |= {"SITELINE_HOME": str(home)} | (env or {})
    return subprocess.run([str(EXE), *argv], env=full, capture_output=True, text=True, timeout=300)


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    """Run the siteline CLI in-process; return (exit status, stdout, stderr)."""
    from siteline.cli import main

    capsys.readouterr()
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def cli_create_site(capsys, fence: Path, *extra: str, name: str = "demo") -> tuple[int, str, str]:
    """``siteline site create`` of the synthetic site's origin and CRS with ``fence``."""
    return run_cli(
        capsys,
        "site",
        "create",
        name,
        "--crs",
        SYNTH.crs,
        "--origin",
        *(str(v) for v in SYNTH.origin),
        "--fence",
        str(fence),
        *extra,
    )


def writable_copy(release_root: Path | str, dest: Path) -> Path:
    """A writable copy of a (read-only, published) release folder at ``dest``."""
    import os

    shutil.copytree(release_root, dest)
    for p in dest.rglob("*"):
        os.chmod(p, 0o755 if p.is_dir() else 0o644)
    return dest


def node_order_key(counts: np.ndarray) -> np.ndarray:
    """The node-order key bit by bit: bit b of x, y, z at 11 - 3 b, 10 - 3 b, 9 - 3 b (b < 4)."""
    c = counts.astype(np.int64)  # two's complement low bits, as the kernel takes them
    key = np.zeros(len(c), np.int64)
    for b in range(4):
        for axis in range(3):
            key |= ((c[:, axis] >> b) & 1) << (11 - 3 * b - axis)
    return key


def ingest_and_tile(cat, settings: Settings, missions: list[Path], site: str = "demo") -> list[int]:  # noqa: ANN001
    """Ingest and tile each mission folder in turn (the library's stages, as a service would); their
    scene ids."""
    from siteline.ingest.stage import ingest_mission
    from siteline.tiles.stage import tile_scene

    ids = []
    for m in missions:
        ids.append(ingest_mission(StageContext(cat, settings), m, site).scene_id)
        tile_scene(StageContext(cat, settings), ids[-1], resources=TilingResources(workers=1))
    return ids


def chromium_path() -> Path:
    """Debian's Chromium for the page tests (`make test` installs it where it is missing). A page test
    without it fails, naming the fix; SITELINE_SKIP_BROWSER=1 skips the page tests on purpose."""
    import pytest

    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found is not None:
        return Path(found)
    if os.environ.get("SITELINE_SKIP_BROWSER") == "1":
        pytest.skip("SITELINE_SKIP_BROWSER=1: the page tests are skipped")
    pytest.fail("no Chromium to open the pages: `make test` installs Debian's (apt-get install chromium); "
                "SITELINE_SKIP_BROWSER=1 skips the page tests on purpose")  # fmt: skip


def manifest_doc(root: Path | str) -> dict:
    """A release's manifest.json as the document it is (what a test asserts of the file itself)."""
    return json.loads((Path(root) / "manifest.json").read_text())
