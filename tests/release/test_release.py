"""Releases: layout, manifest, verify, immutability, bad requests, diff, query, symmetry, object store."""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import sqlalchemy as sa
from PIL import Image
from sitehelpers import epoch_dirs, make_home, manifest_doc, writable_copy

from siteline import pipeline
from siteline.catalog import open_catalog
from siteline.catalog.context import StageContext
from siteline.catalog.models import Pair, Release, Render, Scene
from siteline.catalog.releases import query_items
from siteline.catalog.sites import add_site
from siteline.errors import ImmutableError, NotFoundError, ReleaseError
from siteline.ingest.stage import ingest_mission
from siteline.pairs.render import pair_mask
from siteline.pointpass import TilingResources
from siteline.records.params.pairs import PairParams
from siteline.records.params.release import ReleaseKnobs, ReleaseParams
from siteline.records.release import ReleaseOptions
from siteline.release.manifest import verify_files
from siteline.release.plan import choose_release
from siteline.release.query import diff_releases
from siteline.release.stage import build_release, publish_release
from siteline.schema import validate
from siteline.site.spec import make_site_spec
from siteline.tiles.stage import tile_scene

from .conftest import KNOBS, PARAMS


def test_layout_manifest_and_datasheet(built) -> None:
    settings, cat, pub = built
    root = Path(pub.root)
    doc = manifest_doc(root)
    validate(doc, "release.schema.json", "test")
    assert doc["version"] == "1.0.0" and pub.status == "published"
    assert (root / "README.md").read_text().startswith("# rel 1.0.0")
    assert Image.open(root / "montage.png").size[0] == 1200
    stats = json.loads((root / "stats.json").read_text())
    assert stats["images"] == len(doc["items"]) > 0
    for it in doc["items"]:
        for sub in ("A", "B", "label"):
            assert (root / it["split"] / sub / f"{it['id']}.png").is_file()
        m = np.asarray(Image.open(root / it["split"] / "label" / f"{it['id']}.png"))
        assert set(np.unique(m)) <= {0, 1, 255}
    # two pairs, fewer than the splits: each pair's views in spatial bands, every split populated
    assert {it["split"] for it in doc["items"]} == {"train", "val", "test"}
    assert "spatial bands" in doc["split_rule"]["rule"] and "max_shared_footprint" in doc["split_rule"]
    assert {p for ids in doc["splits"].values() for p in ids} == {it["pair"] for it in doc["items"]}
    lin = doc["lineage"]
    assert lin["parameters"]["scale"] == 0.5 and lin["sites"][0]["name"] == "demo"
    assert all(s["mission_manifest_sha256"] for s in lin["scenes"])
    assert verify_files(root) == []


def test_verify_names_a_flipped_byte(built, tmp_path) -> None:
    _, _, pub = built
    copy = writable_copy(pub.root, tmp_path / "copy")
    victim = next((copy / "train" / "label").glob("*.png"))
    data = bytearray(victim.read_bytes())
    data[len(data) // 2] ^= 0xFF
    victim.write_bytes(bytes(data))
    problems = verify_files(copy)
    assert len(problems) == 1 and victim.name in problems[0] and "sha256" in problems[0]


def test_installed_verify_exits_1_on_a_tampered_release_and_0_once_restored(built) -> None:
    import subprocess
    import sys

    settings, _, pub = built
    exe = Path(sys.executable).with_name("siteline")
    env = {k: v for k, v in os.environ.items() if not k.startswith("SITELINE_")}
    env |= {"SITELINE_HOME": str(settings.home), "SITELINE_DATABASE_URL": settings.database_url}
    victim = next((Path(pub.root) / "train" / "A").glob("*.png"))
    original = victim.read_bytes()
    mode = victim.stat().st_mode
    os.chmod(victim, 0o644)
    try:
        victim.write_bytes(original[:-1] + bytes([original[-1] ^ 0xFF]))
        bad = subprocess.run(
            [str(exe), "release", "verify", "rel", pub.version], env=env, capture_output=True, text=True
        )
    finally:
        victim.write_bytes(original)
        os.chmod(victim, mode)
    assert bad.returncode == 1, (bad.stdout, bad.stderr)
    assert victim.name in bad.stdout and "sha256" in bad.stdout
    good = subprocess.run(
        [str(exe), "release", "verify", "rel", pub.version, "--json"], env=env, capture_output=True, text=True
    )
    assert good.returncode == 0, good.stderr
    assert json.loads(good.stdout)["ok"] is True


@pytest.mark.parametrize("gut", ["manifest", "everything"])
def test_installed_verify_fails_a_gutted_release(built, gut) -> None:
    """Deleting the manifest (or every file) of a published release is tampering: verify checks what
    the catalog recorded at publish, exits 1 and names it, and says which folder it checked."""
    import shutil
    import subprocess
    import sys

    settings, _, pub = built
    exe = Path(sys.executable).with_name("siteline")
    env = {k: v for k, v in os.environ.items() if not k.startswith("SITELINE_")}
    env |= {"SITELINE_HOME": str(settings.home), "SITELINE_DATABASE_URL": settings.database_url}
    root = Path(pub.root)
    backup = root.parent / f".backup-{gut}"
    shutil.copytree(root, backup, symlinks=True)
    try:
        os.chmod(root, 0o755)
        victims = (
            [root / "manifest.json"] if gut == "manifest" else [p for p in root.rglob("*") if p.is_file()]
        )
        for p in victims:
            p.unlink()
        bad = subprocess.run(
            [str(exe), "release", "verify", "rel", pub.version, "--json"],
            env=env,
            capture_output=True,
            text=True,
        )
    finally:
        shutil.rmtree(root)
        shutil.copytree(backup, root, symlinks=True)
        shutil.rmtree(backup)
    assert bad.returncode == 1, (bad.stdout, bad.stderr)
    doc = json.loads(bad.stdout)
    assert doc["ok"] is False and doc["root"] == str(root)
    assert any("manifest.json: missing" in p and "tampered" in p for p in doc["problems"])
    if gut == "everything":
        assert sum("recorded by the catalog" in p for p in doc["problems"]) >= 3
    good = subprocess.run(
        [str(exe), "release", "verify", "rel", pub.version], env=env, capture_output=True, text=True
    )
    assert good.returncode == 0 and f"checked {root}" in good.stdout


def test_a_publish_killed_after_its_record_is_finished_by_the_next_publish(built) -> None:
    """The README's promise: a version recorded as published but left writable (its publish killed
    before make_read_only) is made read-only by the next `release publish`, which exits 0."""
    settings, cat, pub = built
    root = Path(pub.root)
    files = [p for p in root.rglob("*") if p.is_file()]
    for p in [root, *files]:
        os.chmod(p, 0o755 if p.is_dir() else 0o644)
    info = publish_release(StageContext(cat, settings), "rel", pub.version)
    assert info.version == pub.version
    assert not any(p.stat().st_mode & 0o222 for p in [root, *files])


def test_published_release_is_read_only_and_never_republished(built, monkeypatch) -> None:
    settings, cat, pub = built
    some = next(Path(pub.root).rglob("*.png"))
    assert not os.access(some, os.W_OK) or os.geteuid() == 0  # root ignores permission bits
    assert not (some.stat().st_mode & 0o222)
    with pytest.raises(ImmutableError, match="already published"):
        publish_release(StageContext(cat, settings), "rel", "1.0.0")
    same = pipeline.release(
        StageContext(cat, settings), "demo", "rel", KNOBS, options=ReleaseOptions(version="1.0.0")
    )
    assert same.up_to_date and same.status == "published" and same.manifest_sha256 == pub.manifest_sha256
    with pytest.raises(ImmutableError, match="already published"):  # other inputs under that version
        with cat.transaction() as s:
            choice = choose_release(s, "demo", "rel", KNOBS, ReleaseOptions(version="1.0.0"))
        other = replace(choice, params=ReleaseParams(replace(PARAMS, seed=9)))
        build_release(
            StageContext(cat, settings), "demo", "rel", other, options=ReleaseOptions(version="1.0.0")
        )
    # other parameters under that version are refused before any pair is processed
    monkeypatch.setattr(pipeline, "process_pairs", lambda *a, **k: pytest.fail("a pair was processed"))
    other_knobs = ReleaseKnobs.exactly(replace(PARAMS, seed=9))
    with pytest.raises(ImmutableError, match=r"1\.0\.0 is already published .*\(other params\)"):
        pipeline.release(
            StageContext(cat, settings), "demo", "rel", other_knobs, options=ReleaseOptions(version="1.0.0")
        )
    with pytest.raises(ImmutableError), cat.transaction() as s:
        rel = s.query(Release).filter_by(name="rel", version="1.0.0").one()
        rel.parameters = {}


def test_bad_requests_write_nothing(built) -> None:
    settings, cat, _ = built
    with cat.transaction() as s:
        add_site(s, make_site_spec("lonely", "EPSG:32618", (0.0, 0.0, 0.0)))
    before = {p for p in (settings.home / "releases").rglob("*")}
    with pytest.raises(ReleaseError, match="0 scene"):
        pipeline.release(StageContext(cat, settings), "lonely", "x", KNOBS)
    with cat.transaction() as s:
        pid = s.query(Pair).first().id
    with pytest.raises(ReleaseError, match="belongs to site demo"):
        pipeline.release(
            StageContext(cat, settings),
            "lonely2" if False else "lonely",
            "x",
            KNOBS,
            options=ReleaseOptions(pair_ids=[pid]),
        )
    with pytest.raises(NotFoundError):
        publish_release(StageContext(cat, settings), "nope", "1.0.0")
    assert {p for p in (settings.home / "releases").rglob("*")} == before
    with cat.transaction() as s:
        assert s.query(Release).filter_by(name="x").count() == 0


@pytest.mark.slow  # over 25 s on a 2-core machine: `make test-all` runs it
def test_new_parameters_bump_the_major_version_and_diff(built) -> None:
    settings, cat, pub = built
    info = pipeline.release(
        StageContext(cat, settings),
        "demo",
        "rel",
        ReleaseKnobs.exactly(PairParams(scale=0.5, point_size_px=3, views=4, seed=1, min_coverage=0.3)),
    )
    assert info.version == "2.0.0" and info.status == "draft"
    publish_release(StageContext(cat, settings), "rel", "2.0.0")
    with cat.transaction() as s:
        d = diff_releases(s, "rel", "1.0.0", "2.0.0")
    assert d["parameters"]["views"] == [6, 4] and d["parameters"]["seed"] == [0, 1]
    assert d["files"]["changed"] or d["files"]["added"] or d["files"]["removed"]


def test_query_by_change_ratio_and_dates(built) -> None:
    from datetime import UTC, datetime

    _, cat, pub = built
    doc = manifest_doc(pub.root)
    with cat.transaction() as s:
        everything = query_items(s, "rel", "1.0.0")
        high = query_items(s, "rel", "1.0.0", min_change_ratio=0.05)
        none = query_items(s, "rel", "1.0.0", until=datetime(2000, 1, 1, tzinfo=UTC))
    assert len(everything) == len(doc["items"])
    assert all(r["change_ratio"] > 0.05 for r in high) and len(high) <= len(everything)
    assert none == []


def test_items_say_how_much_of_their_change_shows_and_query_by_it(built) -> None:
    _, cat, pub = built
    doc = manifest_doc(pub.root)
    by_id = {it["id"]: it for it in doc["items"]}
    measured = [it for it in doc["items"] if "change_visible" in it]
    assert measured and all(0.0 <= it["change_visible"] <= 1.0 for it in measured)
    assert all(it["change_ratio"] == 0 for it in doc["items"] if "change_visible" not in it)
    cut = sorted(it["change_visible"] for it in measured)[len(measured) // 2]
    with cat.transaction() as s:
        rows = query_items(s, "rel", "1.0.0", min_change_visible=cut)
    assert rows and all(r["change_visible"] >= cut for r in rows)
    assert {r["id"] for r in rows} == {i for i, it in by_id.items() if it.get("change_visible", -1) >= cut}


def test_change_visibility_counts_changed_pixels_that_look_different() -> None:
    from siteline.pairs.render import change_visibility

    a = np.full((4, 5, 3), 100, np.uint8)
    b = a.copy()
    mask = np.zeros((4, 5), np.uint8)
    assert change_visibility(a, b, mask) is None
    mask[:2] = 1  # 10 changed pixels, all looking alike: a slab that gained a floor
    assert change_visibility(a, b, mask) == 0.0
    b[0, :, 1] = 200  # 5 of them now differ in one channel
    b[3, :] = 0  # a difference where nothing changed does not count
    assert change_visibility(a, b, mask) == 0.5


def test_pair_mask_is_symmetric() -> None:
    rng = np.random.default_rng(0)
    hit_a, hit_b = rng.random((20, 30)) < 0.9, rng.random((20, 30)) < 0.9
    ca = rng.choice(np.array([0, 1, 255], np.uint8), (20, 30))
    cb = rng.choice(np.array([0, 1, 255], np.uint8), (20, 30))
    assert np.array_equal(pair_mask(hit_a, ca, hit_b, cb), pair_mask(hit_b, cb, hit_a, ca))
    m = pair_mask(hit_a, ca, hit_b, cb)
    assert (m[~hit_a] == 255).all() and (m[(ca == 1) & hit_a & hit_b & (cb != 255)] == 1).all()


def test_swapping_scenes_gives_the_same_mask(built) -> None:
    settings, cat, pub = built
    from siteline.camera.pinhole import Camera
    from siteline.catalog.scenes import tile_source
    from siteline.pairs.render import LabelledPair, render_pair_view
    from siteline.tiles.reader import SceneTiles

    doc = manifest_doc(pub.root)
    pair = doc["lineage"]["pairs"][0]
    label_uri = settings.store.resolve(pair["labels"]["uri"])  # store:labels/... in the manifest
    with cat.transaction() as s:
        t1, t2 = (SceneTiles.from_source(tile_source(s, pair[side])) for side in ("t1", "t2"))
    forward = LabelledPair.with_labels(t1, t2, label_uri)
    swapped = LabelledPair(forward.t2, forward.t1)
    cam = Camera.look_at((-50.0, -50.0, 35.0), (0.0, 0.0, 0.0), 320, 240, fx=260.0)
    full = PairParams(scale=1.0, point_size_px=1)
    a = render_pair_view(forward, cam, full)
    b = render_pair_view(swapped, cam, full)
    assert np.array_equal(a.mask, b.mask) and (a.mask != 255).any()
    assert np.array_equal(a.a, b.b)
    # fixed disks: every point read covers at least what the level of detail covers
    fixed = {"scale": 0.25, "point_size_px": 1, "lod_factor": 2.0, "splat": "fixed", "fill_px": 0}
    coarse = render_pair_view(forward, cam, PairParams(**fixed))
    every = render_pair_view(forward, cam, PairParams(**fixed, all_points=True))
    assert every.points_read > coarse.points_read  # --all-points: no level of detail
    assert every.coverage_a >= coarse.coverage_a
    # world splats: a coarser read draws wider splats, covering what every point covers, give or
    # take the silhouettes' width
    world = {"scale": 0.25, "point_size_px": 1, "lod_factor": 2.0}
    coarse_w = render_pair_view(forward, cam, PairParams(**world))
    every_w = render_pair_view(forward, cam, PairParams(**world, all_points=True))
    assert every_w.points_read > coarse_w.points_read
    assert abs(every_w.coverage_a - coarse_w.coverage_a) < 0.05
    assert coarse_w.coverage_a > coarse.coverage_a


def test_a_scene_paired_with_itself_reads_one_reader_from_both_threads(built) -> None:
    """A pair renders its two scenes at once, in two threads; paired with itself, a scene's one
    reader (its chunk cache kept small, so the threads evict each other's chunks) serves both and
    draws both sides alike, and as the scene draws in a pair with another."""
    settings, cat, pub = built
    from siteline.camera.pinhole import Camera
    from siteline.catalog.scenes import tile_source
    from siteline.pairs.render import LabelledPair, render_pair_view
    from siteline.tiles.reader import SceneTiles

    pair = manifest_doc(pub.root)["lineage"]["pairs"][0]
    label_uri = settings.store.resolve(pair["labels"]["uri"])
    with cat.transaction() as s:
        t1, t2 = (SceneTiles.from_source(tile_source(s, pair[side])) for side in ("t1", "t2"))
    forward = LabelledPair.with_labels(t1, t2, label_uri)
    alone = LabelledPair(forward.t1, forward.t1)
    alone.t1.cache_bytes = 1 << 16
    params = PairParams(scale=1.0, point_size_px=1)
    for eye in ((-50.0, -50.0, 35.0), (40.0, -20.0, 25.0), (0.0, 30.0, 45.0)):
        cam = Camera.look_at(eye, (0.0, 0.0, 0.0), 320, 240, fx=260.0)
        same = render_pair_view(alone, cam, params)
        assert np.array_equal(same.a, same.b) and same.coverage_a == same.coverage_b > 0.3
        assert np.array_equal(same.a, render_pair_view(forward, cam, params).a)


@pytest.mark.slow  # over 25 s on a 2-core machine: `make test-all` runs it
def test_preset_is_applied_and_recorded(built) -> None:
    from siteline.records.params.presets import PRESETS

    settings, cat, _ = built
    with pytest.raises(ReleaseError, match="unknown preset"):
        ReleaseKnobs(preset="turbo")
    # fast's scale (0.125, for ~5645 px photos) gives 83 x 62 px renders of these 660 px cameras: refused
    before = sorted((settings.home / "releases").rglob("*"))
    with pytest.raises(ReleaseError, match=r"83 x 62 px .* under the 256 px floor: use --scale 0.39"):
        pipeline.release(
            StageContext(cat, settings), "demo", "presetrel", ReleaseKnobs(preset="fast", pair={"views": 3})
        )
    assert sorted((settings.home / "releases").rglob("*")) == before
    knobs = ReleaseKnobs(preset="fast", pair={"scale": 0.5, "views": 3, "min_coverage": 0.2})
    info = pipeline.release(StageContext(cat, settings), "demo", "presetrel", knobs)
    lin = manifest_doc(info.root)["lineage"]
    assert lin["preset"] == "fast" and lin["parameters"]["lod_factor"] == PRESETS["fast"]["lod_factor"]
    assert (lin["parameters"]["scale"], lin["parameters"]["point_size_px"]) == (
        0.5,
        3,
    )  # a knob beats its preset


@pytest.mark.slow  # over 25 s on a 2-core machine: `make test-all` runs it
def test_release_on_s3_matches_the_local_one(built, tmp_path, synth_site, s3_store) -> None:
    """The first pair released from an S3 store: the same images, masks and lineage as the local one."""
    _, _, local = built
    settings = make_home(tmp_path, site_dir=synth_site, store_url=s3_store)
    cat = open_catalog(settings)
    try:
        for m in epoch_dirs(synth_site)[:2]:
            r = ingest_mission(StageContext(cat, settings), m, "demo")
            tile_scene(StageContext(cat, settings), r.scene_id, resources=TilingResources(workers=1))
        info = pipeline.release(StageContext(cat, settings), "demo", "rel", KNOBS)
        pub = publish_release(StageContext(cat, settings), "rel", info.version)
        with cat.transaction() as s:
            uris = [sc.tile_store_uri for sc in s.execute(sa.select(Scene)).scalars()]
            paths = [r.paths["image"] for r in s.execute(sa.select(Render)).scalars()]
    finally:
        cat.dispose()
    assert uris and all(u.startswith(f"{s3_store}/tiles/") and settings.store.is_complete(u) for u in uris)
    assert paths and all(p.startswith(f"{s3_store}/pairs/") and settings.store.exists(p) for p in paths)
    assert not (settings.home / "stores").exists()  # nothing went to the local folder
    assert verify_files(Path(pub.root)) == []

    def by_item(root: str) -> dict[str, str]:
        """sha256 of every image and mask of pair 1, by item and kind (splits differ with the pairs)."""
        doc = manifest_doc(Path(root))
        sha = {f["path"]: f["sha256"] for f in doc["files"]}
        return {
            (it["id"], sub): sha[f"{it['split']}/{sub}/{it['id']}.png"]
            for it in doc["items"]
            if it["pair"] == 1
            for sub in ("A", "B", "label")
        }

    mine = by_item(pub.root)
    assert mine and mine == by_item(local.root)
    scenes = {sc["id"]: sc for sc in manifest_doc(Path(local.root))["lineage"]["scenes"]}
    assert manifest_doc(Path(pub.root))["lineage"]["scenes"] == [scenes[1], scenes[2]]


def test_reused_change_labels_record_their_points(built) -> None:
    """A pair's change labels made by an earlier run (a build killed before its record) are reused
    with their point count, never None in the lineage."""
    from siteline.labelsets.store import open_labelled
    from siteline.pairs.execute import pair_labels
    from siteline.pairs.plan import plan_pair
    from siteline.progress import no_progress

    from .conftest import PARAMS

    settings, cat, _ = built
    with cat.transaction() as s:
        plan = plan_pair(s, settings.store, 1, PARAMS)
    t1, t2 = (open_labelled(sc.tiles, sc.label_set) for sc in (plan.t1, plan.t2))
    labels = pair_labels(plan, t1, t2, settings.store, no_progress)  # the store exists: reused
    counts = labels.counts
    assert labels.points == sum(n for side in counts.values() for n in side.values()) > 0
    assert labels.seconds is None and labels.radius is not None  # reused: no time taken, radius recorded
