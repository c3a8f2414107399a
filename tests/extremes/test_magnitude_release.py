"""The same synthetic site at two coordinate magnitudes gives a byte-identical release (issue: same
inputs, same release at any magnitude). EPSG:3857 keeps grid north on true north at both places, so
only the magnitude differs."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from siteline import pipeline
from siteline.catalog import migrate, open_catalog
from siteline.catalog.context import StageContext
from siteline.catalog.engine import make_engine
from siteline.catalog.sites import add_site
from siteline.config import Settings, sqlite_url
from siteline.ingest.stage import ingest_mission
from siteline.pointpass import TilingResources
from siteline.records.params.pairs import PairParams
from siteline.records.params.release import ReleaseKnobs
from siteline.site.fence import load_fence_geojson
from siteline.site.spec import make_site_spec
from siteline.synth import SynthParams, write_site
from siteline.tiles.stage import tile_scene

ORIGINS = {"small": (1000.0, 2000.0, 80.0), "large": (-8_400_000.0, 5_600_000.0, 80.0)}
PARAMS = PairParams(scale=0.125, views=12, seed=0, min_coverage=0.3)
KNOBS = ReleaseKnobs.exactly(PARAMS, min_image_px=64)


def _release(root: Path, origin: tuple[float, float, float]) -> Path:
    cfg = SynthParams(epochs=2, density_pts_m2=10.0, seed=7, origin=origin, crs="EPSG:3857")
    site_dir = root / "site"
    write_site(site_dir, cfg)
    home = root / "home"
    settings = Settings(home=home, database_url=sqlite_url(home / "catalog.sqlite"))
    engine = make_engine(settings.database_url)
    migrate.upgrade(engine)
    engine.dispose()
    cat = open_catalog(settings)
    ring = load_fence_geojson(site_dir / "fence.geojson", origin)
    with cat.transaction() as s:
        add_site(s, make_site_spec("mag", cfg.crs, origin, [*ring, ring[0]]))
    truth = json.loads((site_dir / "truth" / "site.json").read_text())
    for e in truth["epochs"]:
        r = ingest_mission(StageContext(cat, settings), site_dir / e["mission_dir"], "mag")
        tile_scene(StageContext(cat, settings), r.scene_id, resources=TilingResources(workers=1))
    info = pipeline.release(StageContext(cat, settings), "mag", "rel", KNOBS)
    cat.dispose()
    return Path(info.root)


def _without_origin(lineage: dict) -> dict:
    out = json.loads(json.dumps(lineage))
    for site in out["sites"]:
        site.pop("origin")
    for scene in out["scenes"]:
        scene.pop("mission_manifest_sha256")  # the LAS and photo bytes hold georeferenced coordinates
        scene.pop("registration")  # georegistration transforms carry the origin and its rounding
    for pair in out["pairs"]:
        pair["labels"].pop("uri")  # where this machine's store is
        pair["labels"].pop("seconds")
    return out


@pytest.fixture(scope="module")
def releases(tmp_path_factory) -> dict[str, Path]:
    return {k: _release(tmp_path_factory.mktemp(k), o) for k, o in ORIGINS.items()}


@pytest.mark.e2e
def test_release_is_byte_identical_at_both_magnitudes(releases) -> None:
    a, b = (json.loads((releases[k] / "manifest.json").read_text()) for k in ORIGINS)
    assert a["items"], "the release must hold views for the comparison to mean anything"
    files_a = {f["path"]: f["sha256"] for f in a["files"]}
    files_b = {f["path"]: f["sha256"] for f in b["files"]}
    assert sorted(files_a) == sorted(files_b)
    images = [p for p in files_a if p.endswith(".png")]
    assert len(images) >= 3 * len(a["items"])
    differ = [p for p in images if files_a[p] != files_b[p]]
    assert not differ, f"{len(differ)} of {len(images)} images differ, e.g. {differ[:3]}"
    assert a["items"] == b["items"] and a["splits"] == b["splits"] and a["stats"] == b["stats"]
    assert _without_origin(a["lineage"]) == _without_origin(b["lineage"])
    for p in images:
        data = (releases["small"] / p).read_bytes()
        assert hashlib.sha256(data).hexdigest() == files_a[p]
