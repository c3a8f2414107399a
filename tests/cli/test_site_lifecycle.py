"""Sites that can be corrected, on a real public cloud (the middle of lidR's Topography.laz, ASPRS
1/2/9): a wrong taxonomy or fence fixed with `site update` (a new site version, scenes tiled again,
releases naming the version), the same file ingested into two sites, and scenes and sites deleted
(refused while a published release depends on them). Set-up runs the library in this process; the
commands under test run the installed executable."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest
from realdata import TOPOGRAPHY, centre_xy, later_epoch

from siteline import pipeline
from siteline.catalog import migrate, open_catalog
from siteline.catalog.context import StageContext
from siteline.catalog.engine import make_engine
from siteline.catalog.sites import add_site
from siteline.config import Settings, sqlite_url
from siteline.ingest.options import IngestOptions
from siteline.labelsets.export import export_label_set
from siteline.labelsets.stage import import_labels
from siteline.records.params.release import ReleaseKnobs
from siteline.records.release import ReleaseOptions
from siteline.register.planned import SurveyPlan
from siteline.site.spec import make_site_spec

EXE = Path(sys.executable).parent / "siteline"
ORIGIN = (273500.0, 5274500.0, 800.0)
OPTS = IngestOptions(
    survey=SurveyPlan(altitude_m=100.0, forward_overlap=0.5, side_overlap=0.3)
)  # few cameras
pytestmark = pytest.mark.e2e


def _run(home: Path, *argv: str) -> subprocess.CompletedProcess:
    env = os.environ | {"SITELINE_HOME": str(home)}
    for name in ("SITELINE_DATABASE_URL", "SITELINE_STORE_URL", "PREFECT_API_URL"):
        env.pop(name, None)
    return subprocess.run(
        [str(EXE), *argv], capture_output=True, text=True, env=env, timeout=600, stdin=subprocess.DEVNULL
    )


def _ok(home: Path, *argv: str) -> str:
    r = _run(home, *argv)
    assert r.returncode == 0, f"siteline {' '.join(argv)}: exit {r.returncode}\n{r.stdout}\n{r.stderr}"
    return r.stdout


def _json(home: Path, *argv: str) -> dict:
    return json.loads(_ok(home, *argv, "--json"))


def _water_taxonomy(path: Path) -> Path:
    """The default taxonomy with ASPRS 9 (water) as an ignored class of its own."""
    doc = json.loads((Path(__file__).parents[2] / "schema" / "taxonomy.default.json").read_text())
    doc["name"] = "topo-water"
    doc["classes"].append({"id": 12, "name": "water", "ignore": True, "color": [0, 0, 255]})
    doc["source_codes"]["las"]["9"] = "water"
    path.write_text(json.dumps(doc))
    return path


def _crop(src: Path, out: Path, half_m: float) -> Path:
    """The points of ``src`` within ``half_m`` of its centre (x and y): a smaller real cloud."""
    import laspy
    import numpy as np

    las = laspy.read(src)
    c = centre_xy(src)
    las.points = las.points[
        (np.abs(np.asarray(las.x) - c[0]) < half_m) & (np.abs(np.asarray(las.y) - c[1]) < half_m)
    ]
    las.update_header()
    las.write(out)
    return out


def _home(root: Path, *sites: str) -> tuple[Settings, object]:
    settings = Settings(home=root / "home", database_url=sqlite_url(root / "home" / "catalog.sqlite"))
    engine = make_engine(settings.database_url)
    migrate.upgrade(engine)
    engine.dispose()
    cat = open_catalog(settings)
    with cat.transaction() as s:
        for name in sites:
            add_site(s, make_site_spec(name, "EPSG:2949", ORIGIN))
    return settings, cat


@pytest.fixture(scope="module")
def topo(tmp_path_factory):
    """A home with site topo holding the real file's middle 180 m (for speed) and a later epoch of it
    (a block removed), and an epoch between the two, not yet ingested."""
    tmp = tmp_path_factory.mktemp("lifecycle")
    first = _crop(TOPOGRAPHY, tmp / "topo.laz", 90.0)
    c = centre_xy(first)
    later = later_epoch(
        first, tmp / "later.laz", removed_box=(c[0] - 40, c[1] - 40, c[0] - 10, c[1] - 10), days=400
    )
    middle = later_epoch(first, tmp / "middle.laz", days=200)
    settings, cat = _home(tmp, "topo", "other")
    for path in (first, later):
        pipeline.ingest(StageContext(cat, settings), path, "topo", OPTS, workers=1)
    yield settings.home, first, middle, (settings, cat)
    cat.dispose()


@pytest.mark.slow  # 23 s: a site built, released and rebuilt; `make test-all` runs it
def test_a_wrong_taxonomy_is_fixed_with_site_update(topo, tmp_path) -> None:
    """ASPRS 9 (water) went to ground under the default taxonomy; a taxonomy with a water class makes
    site version 2, tiles both scenes again (label set 1 follows), and a release names the version."""
    home, first, _, (settings, cat) = topo
    scene = _json(home, "scene", "show", "1")
    assert scene["class_histogram"] == {"ground": 4_235, "unclassified": 24_550}
    before = scene["tile_store"]
    # a correction imported before the change: 300 unclassified points of scene 1 are material
    export_label_set(cat, 1, tmp_path / "s1.laz")
    las = laspy.read(tmp_path / "s1.laz")
    codes = np.asarray(las.classification).copy()
    codes[np.flatnonzero(codes == 11)[:300]] = 4  # unclassified -> material
    las.classification = codes
    las.write(tmp_path / "s1_fixed.laz")
    assert import_labels(StageContext(cat, settings), 1, tmp_path / "s1_fixed.laz").version == 2
    out = _ok(home, "site", "update", "topo", "--taxonomy", str(_water_taxonomy(tmp_path / "tax.json")))
    assert "site topo is at version 2" in out and out.count("re-tiled") == 2, out
    # the correction is carried onto the new tiles (its file kept), water mapped anew under it
    assert "corrections of label set 2 carried over as label set 3" in out, out
    assert (home / "exports" / "topo-v1" / "scene-1-label-set-2.laz").exists()
    carried = _json(home, "labels", "show", "1")
    assert carried["version"] == 3 and carried["class_histogram"]["material"] == 300
    assert carried["class_histogram"]["unclassified"] == 24_250
    site = _json(home, "site", "show", "topo")
    assert site["version"] == 2 and site["taxonomy"] == "topo-water" and site["classes"]["water"] == 12
    scene = _json(home, "scene", "show", "1")
    assert scene["class_histogram"] == {"ground": 3_634, "unclassified": 24_550, "water": 601}
    assert scene["tile_store"] != before and not Path(before).exists()
    assert carried["class_histogram"]["water"] == 601
    # a taxonomy that leaves a code of the scenes unmapped is refused, nothing changed
    bad = json.loads((tmp_path / "tax.json").read_text())
    del bad["source_codes"]["las"]["9"]
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    r = _run(home, "site", "update", "topo", "--taxonomy", str(tmp_path / "bad.json"))
    assert r.returncode == 2 and "does not map class codes [9]" in r.stderr, r.stderr
    # a fence over the middle 120 m: version 3; points outside it become ignore
    c = centre_xy(first)
    x0, y0 = c[0] - 60, c[1] - 60
    ring = [[x0, y0], [x0 + 120, y0], [x0 + 120, y0 + 120], [x0, y0 + 120], [x0, y0]]
    local = [[x - ORIGIN[0], y - ORIGIN[1]] for x, y in ring]
    assert pipeline.redefine_site(StageContext(cat, settings), "topo", fence=local, workers=1)[0] == 3
    assert _json(home, "scene", "show", "2")["class_histogram"]["ignore"] > 10_000
    pipeline.release(
        StageContext(cat, settings),
        "topo",
        "topo-cd",
        ReleaseKnobs(pair={"views": 2}),
        options=ReleaseOptions(publish=True),
    )
    root = home / "releases" / "topo-cd" / "1.0.0"
    (site_lineage,) = json.loads((root / "manifest.json").read_text())["lineage"]["sites"]
    assert site_lineage["version"] == 3 and site_lineage["taxonomy"] == "topo-water"
    assert "version 3: taxonomy topo-water" in (root / "README.md").read_text()


def test_one_file_goes_into_two_sites(topo) -> None:
    home, first, _, (settings, cat) = topo
    done = pipeline.ingest(StageContext(cat, settings), first, "other", OPTS, workers=1).ingest
    assert done.created and done.scene_id is not None
    assert not pipeline.ingest(
        StageContext(cat, settings), first, "other", OPTS, workers=1
    ).ingest.created  # once per site
    sites = {s["name"]: s["scenes"] for s in json.loads(_ok(home, "site", "list", "--json"))}
    assert sites["topo"] == 2 and sites["other"] == 1
    _ok(home, "site", "delete", "other", "--yes")
    assert "other" not in _ok(home, "site", "list")
    assert _json(home, "scene", "show", "1")["point_count"] == 28_785  # the shared file's other scene stays


@pytest.mark.slow  # 22 s: an ingest and a two-pair build; `make test-all` runs it
def test_scenes_and_sites_are_deleted_unless_a_published_release_needs_them(topo) -> None:
    """A scene between two is deleted: its pairs, stores and the draft built on them go, and the
    scenes around it are paired again; a scene or site a published release was built from is not."""
    home, _, middle, (settings, cat) = topo
    mid = pipeline.ingest(StageContext(cat, settings), middle, "topo", OPTS, workers=1).ingest.scene_id
    pipeline.release(StageContext(cat, settings), "topo", "mid", ReleaseKnobs(pair={"views": 2}))
    tiles = Path(_json(home, "scene", "show", str(mid))["tile_store"])
    assert tiles.exists() and (home / "releases" / "mid" / ".drafts" / "1.0.0").exists()
    r = _run(home, "scene", "delete", str(mid))
    assert r.returncode == 2 and "pass --yes" in r.stderr and tiles.exists()
    done = _json(home, "scene", "delete", str(mid), "--yes")
    assert done["scenes"] == [mid] and len(done["pairs"]) == 2 and done["drafts"] == ["mid 1.0.0"]
    assert len(done["repaired"]) == 1 and not tiles.exists()
    assert not (home / "releases" / "mid" / ".drafts" / "1.0.0").exists()
    pairs = json.loads(_ok(home, "scene", "list", "--site", "topo", "--json"))["pairs"]
    assert [(p["t1"], p["t2"]) for p in pairs] == [(1, 2)]
    # topo-cd 1.0.0 (the first test's) was published from pair (1, 2)
    for argv in (("scene", "delete", "1", "--yes"), ("site", "delete", "topo", "--yes")):
        r = _run(home, *argv)
        assert r.returncode == 2 and "published release(s) topo-cd 1.0.0" in r.stderr, r.stderr
    assert _json(home, "scene", "show", "1")["status"] == "tiled"
