"""Corrected labels come back as new label-set versions: export, edit with laspy as an outside editor
would, import; exactly the edited points change, earlier versions stay readable, bad files leave
nothing behind."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import laspy
import numpy as np
import pytest
from sitehelpers import run_cli

from labelsets.edits import centre_box, export, shuffled, versions
from siteline.catalog.context import StageContext
from siteline.catalog.labelsets import label_set
from siteline.errors import LabelSetError, PointCloudError
from siteline.labelsets.stage import ImportOptions, import_labels
from siteline.pointpass import TilingResources, read_labels_vlr
from siteline.stores import layout

GROUND, BUILDING, MATERIAL, WORKS = 1, 2, 4, 6
SITELINE = Path(os.environ.get("VIRTUAL_ENV", ".venv")) / "bin" / "siteline"


def _cli(settings, *argv: str) -> subprocess.CompletedProcess:  # noqa: ANN001
    exe = SITELINE if SITELINE.exists() else Path(".venv/bin/siteline").resolve()
    env = os.environ | {"SITELINE_HOME": str(settings.home), "SITELINE_DATABASE_URL": settings.database_url}
    env.pop("PREFECT_API_URL", None)
    return subprocess.run([str(exe), *argv], capture_output=True, text=True, env=env, timeout=120)


def test_cli_export_edit_import_changes_exactly_the_edited_points(
    scenes, tmp_path, capsys, monkeypatch
) -> None:
    settings, cat = scenes
    before = versions(cat, 1)
    out = tmp_path / "scene1.laz"
    r = _cli(settings, "scene", "export", "1", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    original = laspy.read(out)
    doc = read_labels_vlr(original.header, out)
    assert doc["scene"] == 1 and doc["site"] == "demo" and doc["label_set_version"] == before[-1]
    assert {c["name"] for c in doc["taxonomy"]["classes"]} >= {"ground", "material", "ignore"}
    assert np.unique(original.gps_time).size > 1 and set(np.unique(original.return_number)) >= {1}
    cls0 = np.asarray(original.classification).copy()

    edited, perm = shuffled(laspy.read(out))
    cls = np.asarray(edited.classification).copy()
    region = centre_box(edited, 15.0) & (cls == GROUND)
    assert region.sum() > 100
    cls[region] = MATERIAL
    edited.classification = cls
    fixed = tmp_path / "fixed.laz"
    edited.write(fixed)

    r = _cli(settings, "labels", "import", "1", str(fixed), "--note", "stockpile by the crane", "--json")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert res["created"] and res["version"] == before[-1] + 1 and res["parent_version"] == before[-1]
    assert res["matched"] == len(cls0) and res["unmatched"] == res["duplicated"] == res["untouched"] == 0
    assert res["changed"] == int(region.sum()) and res["changes"] == {"ground->material": int(region.sum())}
    assert versions(cat, 1) == [*before, res["version"]]

    # the new version differs from its parent exactly at the edited points, wherever the editor put them
    new = export(cat, 1, tmp_path / "v_new.las", res["version"])
    changed = np.zeros(len(cls0), dtype=bool)
    changed[perm[region]] = True
    assert np.array_equal(np.asarray(new.classification) != cls0, changed)
    assert np.all(np.asarray(new.classification)[changed] == MATERIAL)
    # the parent is untouched and still readable
    old = export(cat, 1, tmp_path / "v_old.las", before[-1])
    assert np.array_equal(np.asarray(old.classification), cls0)

    r = _cli(settings, "labels", "diff", "1", "--json")
    assert r.returncode == 0, r.stderr
    diff = json.loads(r.stdout)
    assert diff["from"] == before[-1] and diff["to"] == res["version"]
    assert diff["changed"] == int(region.sum()) and diff["changes"] == {"ground->material": int(region.sum())}
    monkeypatch.setenv("SITELINE_HOME", str(settings.home))
    monkeypatch.setenv("SITELINE_DATABASE_URL", settings.database_url)
    monkeypatch.delenv("PREFECT_API_URL", raising=False)
    code, stdout, _ = run_cli(capsys, "labels", "show", "1", "--json")
    shown = json.loads(stdout)
    assert shown["note"] == "stockpile by the crane" and shown["changed_points"] == int(region.sum())
    assert shown["class_histogram"]["material"] == int((cls0 == MATERIAL).sum() + region.sum())
    code, stdout, _ = run_cli(capsys, "labels", "list", "1", "--json")
    assert [v["version"] for v in json.loads(stdout)] == versions(cat, 1)
    # importing the same file again changes nothing: no new version, exit 0
    code, stdout, _ = run_cli(capsys, "labels", "import", "1", str(fixed), "--json")
    assert code == 0 and not json.loads(stdout)["created"]
    assert versions(cat, 1) == [*before, res["version"]]


def test_region_export_is_corrected_alone(scenes, tmp_path) -> None:
    settings, cat = scenes
    parent = versions(cat, 1)[-1]
    full = export(cat, 1, tmp_path / "full.las")
    xs, ys = np.asarray(full.x) - settings_origin(cat)[0], np.asarray(full.y) - settings_origin(cat)[1]
    cx, cy = float(np.median(xs)), float(np.median(ys))
    bounds = [cx - 30, cy - 30, cx, cy]
    region = export(cat, 1, tmp_path / "region.laz", bounds=bounds)
    assert 0 < len(region.points) < len(full.points)
    cls = np.asarray(region.classification).copy()
    target = (cls != 255) & (cls != WORKS)
    cls[target] = WORKS
    region.classification = cls
    region.write(tmp_path / "region_fixed.laz")

    res = import_labels(
        StageContext(cat, settings), 1, tmp_path / "region_fixed.laz", ImportOptions(note="formwork")
    )
    assert res.created and res.parent_version == parent
    assert res.matched == len(region.points) and res.untouched == len(full.points) - len(region.points)
    assert res.changed == int(target.sum())
    after = export(cat, 1, tmp_path / "after.las")
    inside = (xs >= bounds[0]) & (xs <= bounds[2]) & (ys >= bounds[1]) & (ys <= bounds[3])
    before_cls, after_cls = np.asarray(full.classification), np.asarray(after.classification)
    assert np.array_equal(before_cls[~inside], after_cls[~inside])  # outside: the previous version's
    assert np.all(after_cls[inside & (before_cls != 255)] == WORKS)


def settings_origin(cat) -> tuple[float, float, float]:  # noqa: ANN001
    from siteline.catalog.models import Site

    with cat.transaction() as s:
        return s.get(Site, 1).origin


def test_taxonomy_map_reads_another_coding(scenes, tmp_path) -> None:
    settings, cat = scenes
    las = export(cat, 2, tmp_path / "s2.las")
    site_to_asprs = {GROUND: 2, BUILDING: 6, 3: 64, MATERIAL: 65, 5: 66, WORKS: 67, 7: 3, 8: 68, 255: 0}
    cls = np.asarray(las.classification)
    coded = np.array([site_to_asprs.get(int(c), 0) for c in range(256)], np.uint8)[cls]
    edit = centre_box(las, 10.0) & (cls == GROUND)
    coded[edit] = 6  # ground -> building
    las.classification = coded
    las.write(tmp_path / "s2_asprs.las")
    mapping = {str(v): k for k, v in site_to_asprs.items()}
    (tmp_path / "map.json").write_text(json.dumps(mapping))
    with pytest.raises(LabelSetError, match=r"class codes \[.*65.*\].*--taxonomy-map"):
        import_labels(
            StageContext(cat, settings), 2, tmp_path / "s2_asprs.las"
        )  # ASPRS codes read as site ids
    from siteline.labelsets.mapping import read_taxonomy_map

    res = import_labels(
        StageContext(cat, settings),
        2,
        tmp_path / "s2_asprs.las",
        ImportOptions(read_taxonomy_map(tmp_path / "map.json")),
    )
    assert res.changed == int(edit.sum()) and res.changes == {"ground->building": int(edit.sum())}


def test_a_file_without_its_record_needs_to_say_how_its_codes_read(scenes, tmp_path) -> None:
    """An export whose siteline record an editor dropped, recoded to ASPRS (ground 2, building 6):
    2 is also a site id (building), so without --taxonomy-map it is refused, exit 2, nothing
    written; ``--taxonomy-map las`` reads it through the site taxonomy's LAS codes, and an unchanged
    file read as ``site`` ids makes no version."""
    settings, cat = scenes
    before = versions(cat, 2)
    las = export(cat, 2, tmp_path / "s2.las")
    cls = np.asarray(las.classification)
    keep = np.isin(cls, [GROUND, BUILDING])
    header = laspy.LasHeader(point_format=las.header.point_format.id, version=str(las.header.version))
    header.offsets, header.scales = las.header.offsets, las.header.scales
    header.add_crs(las.header.parse_crs())
    bare = laspy.LasData(header)  # no siteline record
    bare.points = laspy.ScaleAwarePointRecord(
        las.points.array[keep], header.point_format, header.scales, header.offsets
    )
    asprs = np.where(cls[keep] == GROUND, 2, 6).astype(np.uint8)
    edit = centre_box(bare, 10.0) & (asprs == 2)
    asprs[edit] = 6  # ground -> building
    bare.classification = asprs
    bare.write(tmp_path / "asprs.las")
    r = _cli(settings, "labels", "import", "2", str(tmp_path / "asprs.las"))
    assert r.returncode == 2 and "carries no siteline label-set record" in r.stderr, r.stderr
    assert "ASPRS 2 and 5 would read as building and vehicle" in r.stderr and "--taxonomy-map las" in r.stderr
    assert versions(cat, 2) == before
    r = _cli(
        settings, "labels", "import", "2", str(tmp_path / "asprs.las"), "--taxonomy-map", "las", "--json"
    )
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert res["changed"] == int(edit.sum()) and res["changes"] == {"ground->building": int(edit.sum())}
    site = export(cat, 2, tmp_path / "now.las")
    site.write(tmp_path / "now.las")
    r = _cli(settings, "labels", "import", "2", str(tmp_path / "now.las"), "--taxonomy-map", "site", "--json")
    assert r.returncode == 0 and not json.loads(r.stdout)["created"], r.stderr
    r = _cli(settings, "labels", "import", "2", str(tmp_path / "now.las"), "--taxonomy-map", "nosuch.json")
    assert r.returncode == 2 and "taxonomy map nosuch.json does not exist" in r.stderr


def _store_listing(settings, scene_id: int) -> list[str]:  # noqa: ANN001
    root = Path(layout.label_set(settings.store, scene_id, 1)).parent
    return sorted(p.name for p in root.iterdir()) if root.exists() else []


def _refused(cat, settings, path: Path, error, match: str, **kw) -> None:  # noqa: ANN001
    before, listing = versions(cat, 1), _store_listing(settings, 1)
    with pytest.raises(error, match=match):
        import_labels(StageContext(cat, settings), 1, path, ImportOptions(**kw))
    assert versions(cat, 1) == before
    assert _store_listing(settings, 1) == listing
    assert not list((settings.home / "tmp").glob("labels-scene-*"))


def test_bad_files_are_refused_and_leave_nothing(scenes, tmp_path) -> None:
    settings, cat = scenes
    other = export(cat, 2, tmp_path / "scene2.las")
    _refused(cat, settings, tmp_path / "scene2.las", LabelSetError, r"exported from scene 2 of site demo")

    # the same file with its siteline record dropped (as some editors do): refused by matching
    bare = laspy.LasData(laspy.LasHeader(point_format=7, version="1.4"))
    bare.header.scales, bare.header.offsets = other.header.scales, other.header.offsets
    bare.header.add_crs(other.header.parse_crs())
    bare.points = other.points.copy()
    bare.write(tmp_path / "scene2_bare.las")
    _refused(
        cat,
        settings,
        tmp_path / "scene2_bare.las",
        LabelSetError,
        r"match no point of scene 1",
        taxonomy_map="site",
    )

    mine = export(cat, 1, tmp_path / "scene1.las")
    n = len(mine.points)
    dup = laspy.read(tmp_path / "scene1.las")
    dup.points = laspy.ScaleAwarePointRecord(
        np.concatenate([mine.points.array, mine.points.array[: n // 50]]), mine.header.point_format,
        mine.header.scales, mine.header.offsets,
    )  # fmt: skip
    dup.write(tmp_path / "dup.las")
    _refused(
        cat, settings, tmp_path / "dup.las", LabelSetError, rf"{n // 50:,} repeat a point already matched"
    )
    # under the documented threshold a few repeats are tolerated (and reported)
    few = laspy.read(tmp_path / "scene1.las")
    cls = np.asarray(few.classification).copy()
    cls[np.flatnonzero((cls != 255) & (cls != 8))[:10]] = 8  # ten points become workers
    few.classification = cls
    few.points = laspy.ScaleAwarePointRecord(
        np.concatenate([few.points.array, few.points.array[:3]]), few.header.point_format,
        few.header.scales, few.header.offsets,
    )  # fmt: skip
    few.write(tmp_path / "few.las")
    res = import_labels(StageContext(cat, settings), 1, tmp_path / "few.las")
    assert res.duplicated == 3 and res.created and res.changed == 10

    bad = laspy.read(tmp_path / "scene1.las")
    cls = np.asarray(bad.classification).copy()
    cls[:7] = 77
    bad.classification = cls
    bad.write(tmp_path / "codes.las")
    _refused(cat, settings, tmp_path / "codes.las", LabelSetError, r"class codes \[77\] \(7 points\)")

    mine.write(tmp_path / "scene1.laz")
    data = (tmp_path / "scene1.laz").read_bytes()
    (tmp_path / "cut.laz").write_bytes(data[: len(data) // 2])
    _refused(cat, settings, tmp_path / "cut.laz", PointCloudError, r"cut\.laz")
    _refused(cat, settings, tmp_path / "missing.laz", LabelSetError, r"missing\.laz does not exist")


def test_unknown_version_is_named(scenes) -> None:
    _, cat = scenes
    with cat.transaction() as s, pytest.raises(LabelSetError, match=r"no label-set version 99 \(it has 1"):
        label_set(s, 1, 99)


def test_a_label_set_of_another_tiling_is_refused(scenes, tmp_path) -> None:
    """A label-set store follows the order of the tile arrays it was written for; after a re-tile it
    is refused, naming the file to import again, instead of read misaligned."""
    from siteline.catalog.labelsets import labelled_source
    from siteline.catalog.models import Scene
    from siteline.labelsets.store import open_labelled

    settings, cat = scenes
    las = export(cat, 2, tmp_path / "s2.las")
    cls = np.asarray(las.classification).copy()
    cls[np.flatnonzero((cls != 255) & (cls != 8))[:5]] = 8
    las.classification = cls
    las.write(tmp_path / "s2_fixed.las")
    res = import_labels(StageContext(cat, settings), 2, tmp_path / "s2_fixed.las")
    with cat.transaction() as s:
        scene = s.get(Scene, 2)
        saved = scene.statistics
        scene.statistics = {**saved, "tiles": {**saved["tiles"], "checksum": "another tiling"}}
    try:
        with cat.transaction() as s, pytest.raises(LabelSetError, match=r"another tiling.*s2_fixed\.las"):
            open_labelled(*labelled_source(s, 2, res.version))
        with cat.transaction() as s:
            open_labelled(*labelled_source(s, 2, 1))  # version 1 is the tile store's own classes
    finally:
        with cat.transaction() as s:
            s.get(Scene, 2).statistics = saved


def test_reimporting_an_unchanged_export_makes_no_version_even_at_the_fence(tmp_path) -> None:
    """Points 0.1 mm inside the fence round (1 mm tile quantum) to 0.3 mm outside it: ingest kept them,
    and re-importing the unchanged export must not flip them to ignore (it made a new label set)."""
    import datetime as dt

    from sitehelpers import make_home

    from siteline.catalog import open_catalog
    from siteline.catalog.sites import add_site
    from siteline.ingest.options import IngestOptions
    from siteline.ingest.stage import ingest_mission
    from siteline.pointpass import write_las
    from siteline.site.spec import make_site_spec
    from siteline.tiles.stage import tile_scene

    origin = (445_000.0, 5_030_000.0, 80.0)
    settings = make_home(tmp_path)  # site demo without a fence; add one with an edge at x = 10.0007 m
    cat = open_catalog(settings)
    edge = 10.0007
    with cat.transaction() as s:
        add_site(
            s,
            make_site_spec(
                "fenced", "EPSG:32618", origin, [(-20, -20), (edge, -20), (edge, 20), (-20, 20), (-20, -20)]
            ),
        )
    rng = np.random.default_rng(0)
    xy = np.c_[rng.uniform(-19, 9, 3000), rng.uniform(-19, 19, 3000)]
    near = np.c_[np.full(40, edge - 0.0001), np.linspace(-15, 15, 40)]  # 0.1 mm inside; the tiles hold 10.001
    local = np.r_[np.c_[xy, rng.normal(0, 0.02, 3000)], np.c_[near, np.zeros(40)]]
    mission = tmp_path / "m"
    write_las(mission / "cloud.las", local + np.asarray(origin), crs="EPSG:32618",
              classification=np.full(len(local), 2, np.uint8), scale=0.0001)  # fmt: skip
    when = dt.datetime(2024, 6, 1, tzinfo=dt.UTC)
    r = ingest_mission(StageContext(cat, settings), mission, "fenced", IngestOptions(captured_at=when))
    tile_scene(StageContext(cat, settings), r.scene_id, resources=TilingResources(workers=1))
    assert r.scan is not None and r.scan.outside_fence == 0
    export(cat, r.scene_id, tmp_path / "unchanged.las")
    res = import_labels(StageContext(cat, settings), r.scene_id, tmp_path / "unchanged.las")
    assert not res.created and res.changed == 0, res
    assert versions(cat, r.scene_id) == [1]
    cat.dispose()


@pytest.mark.parametrize("taxonomy", [{}, {"name": "edited"}, {"name": "x", "classes": "ground"}])
def test_a_record_whose_taxonomy_an_editor_mangled_is_refused_as_another_taxonomy(tmp_path, taxonomy) -> None:
    """The record's taxonomy is read as the site's record type; one that is not a taxonomy any more is
    refused like another taxonomy (the fix named), not with a schema error about the file's record."""
    from siteline.labelsets.execute import _check_origin
    from siteline.records.labelsets import ExportedLabels
    from siteline.schema import json_doc
    from siteline.site.spec import make_site_spec

    site = make_site_spec("yard", "EPSG:32618", (445_000.0, 5_030_000.0, 80.0))
    path = tmp_path / "edited.las"
    own = ExportedLabels("yard", 3, 1, "site class ids", json_doc(site.taxonomy.to_dict()))
    _check_origin(own, 3, site, path, None)  # the site's own taxonomy: its class ids are the site's
    with pytest.raises(LabelSetError, match=r"edited\.las .*class ids differ.*--taxonomy-map"):
        _check_origin(ExportedLabels("yard", 3, 1, "site class ids", taxonomy), 3, site, path, None)
