"""Ingest of synthetic missions: scenes, pairs, idempotence, georegistration, extremes."""

from __future__ import annotations

import json
import shutil
import threading
from datetime import UTC, datetime
from pathlib import Path

import laspy
import numpy as np
import pytest
import sqlalchemy as sa
from sitehelpers import copy_mission, epoch_dirs, make_home

from siteline.camera.pinhole import Camera
from siteline.catalog import open_catalog
from siteline.catalog.context import StageContext
from siteline.catalog.models import Camera as CameraRow
from siteline.catalog.models import Mission, Pair, Scene
from siteline.catalog.scenes import get_scene, list_scenes, scene_cameras, tile_source
from siteline.catalog.sites import get_site
from siteline.errors import RegistrationError
from siteline.ingest.options import IngestOptions
from siteline.ingest.stage import ingest_mission
from siteline.pointpass import TilingResources, write_las
from siteline.synth import LAS_RELPATH, SynthParams, write_site
from siteline.tiles.stage import tile_scene

# a bare LAS without an absolute GPS time cannot tell its capture time: the tests give it
DATED = IngestOptions(captured_at=datetime(2024, 6, 1, 12, tzinfo=UTC))


def _truth_cameras(site, index):
    name = epoch_dirs(site)[index].name
    return {
        t["name"]: Camera.from_dict(t["camera"])
        for t in json.loads((site / "truth" / name / "cameras.json").read_text())
    }


def test_two_epochs_become_two_scenes_and_a_pair(cat, site_settings, synth_site) -> None:
    e0, e1 = epoch_dirs(synth_site)[:2]
    r0 = ingest_mission(StageContext(cat, site_settings), e0, "demo")
    r1 = ingest_mission(StageContext(cat, site_settings), e1, "demo")
    assert r0.created and r1.created and r1.pairs
    with cat.transaction() as s:
        scenes = list_scenes(s, get_site(s, "demo"))
        assert [sc.id for sc in scenes] == [r0.scene_id, r1.scene_id]
        pair = s.execute(sa.select(Pair)).scalar_one()
        assert (pair.t1_scene_id, pair.t2_scene_id) == (r0.scene_id, r1.scene_id)
        assert scenes[0].capture_time < scenes[1].capture_time
        alignment = scenes[1].registration.alignment
        assert alignment is not None and alignment.translation_m < 0.5
    again = ingest_mission(StageContext(cat, site_settings), e0, "demo")
    assert not again.created and "nothing new" in again.message and again.scene_id == r0.scene_id
    with cat.transaction() as s:
        assert s.execute(sa.select(sa.func.count(Mission.id))).scalar_one() == 2


def test_georegistration_recovers_true_poses(cat, site_settings, synth_site) -> None:
    r = ingest_mission(StageContext(cat, site_settings), epoch_dirs(synth_site)[0], "demo")
    assert r.registration.source == "colmap" and (r.registration.rms_m or 1) < 0.01
    truth = _truth_cameras(synth_site, 0)
    with cat.transaction() as s:
        cams = dict(scene_cameras(s, r.scene_id))
    assert set(cams) == set(truth)
    for name, cam in cams.items():
        assert np.linalg.norm(cam.center - truth[name].center) < 0.01
        assert np.abs(cam.R - truth[name].R).max() < 1e-6


def test_files_are_copied_beside_the_scan_and_appear_only_after_the_checks(
    cat, site_settings, synth_site, monkeypatch
) -> None:
    """The mission's files are copied while its point cloud is read (the copy overlaps the scan),
    under temporary names: no blob appears before every check passed, and none is left over."""
    import time

    import siteline.ingest.stage as stage_mod

    mission = epoch_dirs(synth_site)[0]
    n_files = sum(1 for p in mission.rglob("*") if p.is_file())
    blobs = Path(site_settings.store.url) / "blobs"
    during: list[list[str]] = []
    scan = stage_mod.execute_ingest

    def watched(*args, **kwargs):
        deadline = time.monotonic() + 60
        names: list[str] = []
        while time.monotonic() < deadline and len(names) < n_files:
            names = [p.name for p in blobs.rglob("*") if p.is_file()] if blobs.exists() else []
            time.sleep(0.01)
        during.append(names)
        return scan(*args, **kwargs)

    monkeypatch.setattr(stage_mod, "execute_ingest", watched)
    ingest_mission(StageContext(cat, site_settings), mission, "demo")
    assert len(during[0]) == n_files and all(".tmp-" in name for name in during[0])
    after = [p.name for p in blobs.rglob("*") if p.is_file()]
    assert len(after) == n_files + 1 and not [name for name in after if ".tmp-" in name]


def test_copy_store_holds_every_file_and_reference_keeps_paths(
    cat, site_settings, synth_site, tmp_path
) -> None:
    mission = epoch_dirs(synth_site)[0]
    ingest_mission(StageContext(cat, site_settings), mission, "demo")
    blobs = [p for p in (Path(site_settings.store.url) / "blobs").rglob("*") if p.is_file()]
    n_files = sum(1 for p in mission.rglob("*") if p.is_file())
    assert len(blobs) == n_files + 1  # every file, plus the scene's alignment sample
    other = make_home(tmp_path / "ref", site_dir=synth_site)
    c2 = open_catalog(other)
    ingest_mission(StageContext(c2, other), mission, "demo", IngestOptions(storage="reference"))
    assert len([p for p in (Path(other.store.url) / "blobs").rglob("*") if p.is_file()]) == 1
    with c2.transaction() as s:
        m = s.execute(sa.select(Mission)).scalar_one()
        assert m.storage == "reference" and m.root_uri == str(mission.resolve())
    c2.dispose()


def test_xmp_poses_without_colmap_model(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    shutil.rmtree(mission / "colmap")
    r = ingest_mission(StageContext(cat, site_settings), mission, "demo")
    assert r.registration.source == "xmp"
    truth = _truth_cameras(synth_site, 0)
    with cat.transaction() as s:
        for name, cam in scene_cameras(s, r.scene_id):
            assert np.linalg.norm(cam.center - truth[name].center) < 0.01


def settings_site_fence(settings):  # noqa: ANN001, ANN201
    """The fence of the demo site of ``settings``' catalog."""
    from siteline.catalog.sites import get_site, site_of

    cat = open_catalog(settings)
    with cat.transaction() as s:
        fence = site_of(s, get_site(s, "demo").id).fence
    cat.dispose()
    return fence


def test_lidar_only_mission_gets_planned_cameras_over_its_data(tmp_path) -> None:
    """No photos: the cameras are planned from the point cloud over the site's fence, recorded with
    their source, and every one stands over the data at the stated height above its ground."""
    site = tmp_path / "site"
    write_site(site, SynthParams(epochs=1, density_pts_m2=1.0, seed=2, photos=False, colmap=False))
    settings = make_home(tmp_path, site_dir=site)
    cat = open_catalog(settings)
    r = ingest_mission(StageContext(cat, settings), epoch_dirs(site)[0], "demo")
    assert r.created and r.registration.source == "planned"
    survey = r.registration.to_dict()["survey"]
    from siteline.register.planned import SurveyPlan, auto_altitude, tallest_structure
    from siteline.site.fence import fence_area_m2
    from siteline.site.taxonomy import default_taxonomy

    # no --altitude: chosen from the cloud's tallest structure (the 42 m crane), density and the
    # fence's area, and the reason recorded
    tallest = tallest_structure(r.scan.survey_sample, default_taxonomy().ignored_lut())
    assert tallest is not None and 40 < tallest.height_m < 46
    altitude, why = auto_altitude(
        SurveyPlan(), r.scan.density_pts_m2, fence_area_m2(settings_site_fence(settings)), (tallest, "crane")
    )
    assert altitude >= tallest.height_m + 15.0 and "crane" in why
    assert (
        r.registration.over == "site fence"
        and survey["altitude_m"] == altitude
        and survey["altitude_why"] == why
    )
    with cat.transaction() as s:
        sc = get_scene(s, r.scene_id)
        assert sc.capture_time.year == 2024  # from the raw folder name
        cams = scene_cameras(s, sc.id)
        sources = {c.source for c in s.query(CameraRow).filter_by(scene_id=sc.id)}
        bounds = sc.statistics.scan.bounds_min, sc.statistics.scan.bounds_max
    assert len(cams) == r.registration.images > 10 and sources == {"planned"}
    nadir = [c for n, c in cams if "nadir" in n]
    assert nadir and all(np.allclose(c.forward, [0, 0, -1], atol=1e-5) for c in nadir)
    for name, cam in cams:
        # nadir cameras over the data (the grid is buffered by half a line spacing); obliques stand
        # back from the edge so that they look at it at 45 degrees from the altitude
        margin = 15.0 if "nadir" in name else altitude + 5.0
        assert bounds[0][0] - margin <= cam.center[0] <= bounds[1][0] + margin, name
        assert bounds[0][1] - margin <= cam.center[1] <= bounds[1][1] + margin, name
        assert 0.7 * altitude < cam.center[2] - bounds[0][2] < 1.75 * altitude
    # the same cloud and settings plan the same cameras (another home, the same mission)
    again = make_home(tmp_path / "again", site_dir=site)
    cat2 = open_catalog(again)
    r2 = ingest_mission(StageContext(cat2, again), epoch_dirs(site)[0], "demo")
    with cat2.transaction() as s:
        assert scene_cameras(s, r2.scene_id) == cams
    cat.dispose()
    cat2.dispose()


def test_extreme_las_scale_and_offset_survive_exactly(tmp_path) -> None:
    rng = np.random.default_rng(0)
    local = np.round(rng.uniform(-50, 50, (5000, 3)), 4)
    local[:, 2] = np.abs(local[:, 2]) / 10
    origin = (445_000.0, 5_030_000.0, 80.0)
    geo = local + np.asarray(origin)
    mission = tmp_path / "m"
    write_las(
        mission / LAS_RELPATH, geo, crs="EPSG:32618", classification=np.full(5000, 2, np.uint8), scale=0.0001
    )
    las = laspy.read(mission / LAS_RELPATH)
    assert np.allclose(las.header.scales, 1e-4) and las.header.offsets[1] > 5_000_000
    exact = np.c_[las.x, las.y, las.z] - np.asarray(origin)
    settings = make_home(tmp_path)
    cat = open_catalog(settings)
    r = ingest_mission(StageContext(cat, settings), mission, "demo", DATED)
    with cat.transaction() as s:
        sc = s.get(Scene, r.scene_id)
        assert sc.bounds["min"] == exact.min(axis=0).tolist()
        assert sc.bounds["max"] == exact.max(axis=0).tolist()
    assert np.abs(exact - local).max() < 0.5e-4 + 1e-9
    cat.dispose()


def test_other_crs_is_transformed_in_float64(tmp_path) -> None:
    import pyproj

    rng = np.random.default_rng(1)
    local = rng.uniform(-40, 40, (3000, 3))
    origin = np.array([445_000.0, 5_030_000.0, 80.0])
    geo = local + origin
    t = pyproj.Transformer.from_crs("EPSG:32618", "EPSG:32617", always_xy=True)
    x, y = t.transform(geo[:, 0], geo[:, 1])
    mission = tmp_path / "m"
    write_las(
        mission / LAS_RELPATH,
        np.c_[x, y, geo[:, 2]],
        crs="EPSG:32617",
        classification=np.full(3000, 2, np.uint8),
    )
    settings = make_home(tmp_path)
    cat = open_catalog(settings)
    r = ingest_mission(StageContext(cat, settings), mission, "demo", DATED)
    assert r.scan is not None and r.scan.transformed and r.scan.source_crs == "EPSG:32617"
    with cat.transaction() as s:
        sc = s.get(Scene, r.scene_id)
        assert np.allclose(sc.bounds["min"], local.min(axis=0), atol=2e-3)
        assert np.allclose(sc.bounds["max"], local.max(axis=0), atol=2e-3)
    cat.dispose()


def _dropped(synth_site, tmp_path, metres: float):  # noqa: ANN001, ANN202
    """Epoch 1 with its cloud dropped by ``metres`` (a vertical datum slip: ellipsoidal vs orthometric
    heights is the classic one)."""
    mission = copy_mission(synth_site, 1, tmp_path / f"drop{metres:g}")
    las = laspy.read(mission / LAS_RELPATH)
    las.z = np.asarray(las.z) - metres
    las.write(mission / LAS_RELPATH)
    return mission


def test_a_scene_a_metre_off_is_co_registered_and_corrected(cat, site_settings, synth_site, tmp_path) -> None:
    """A 1 m slip is registered onto the previous scene and the correction applied: the scene's tiles
    lie where the previous scene's do (its ground at the same height)."""
    from siteline.tiles.reader import SceneTiles

    r0 = ingest_mission(StageContext(cat, site_settings), epoch_dirs(synth_site)[0], "demo")
    r = ingest_mission(StageContext(cat, site_settings), _dropped(synth_site, tmp_path, 1.0), "demo")
    a = r.registration.alignment
    assert a is not None and a.applied and 0.95 < a.translation_m < 1.05 and a.residual_m < 0.05
    for sid in (r0.scene_id, r.scene_id):
        tile_scene(StageContext(cat, site_settings), sid, resources=TilingResources(workers=1))
    with cat.transaction() as s:
        stores = [tile_source(s, sid) for sid in (r0.scene_id, r.scene_id)]
    z = [np.median(SceneTiles.from_source(src).points(resolution=1.0).xyz_m[:, 2]) for src in stores]
    assert abs(z[0] - z[1]) < 0.1


def test_a_scene_metres_off_is_refused_unless_accepted_then_recorded_not_applied(
    cat, site_settings, synth_site, tmp_path
) -> None:
    ingest_mission(StageContext(cat, site_settings), epoch_dirs(synth_site)[0], "demo")
    mission = _dropped(synth_site, tmp_path, 10.0)
    with pytest.raises(RegistrationError, match="cannot be co-registered"):
        ingest_mission(StageContext(cat, site_settings), mission, "demo")
    with cat.transaction() as s:
        assert s.execute(sa.select(sa.func.count(Scene.id))).scalar_one() == 1
    r = ingest_mission(
        StageContext(cat, site_settings), mission, "demo", IngestOptions(accept_misalignment=True)
    )
    a = r.registration.alignment
    assert a is not None and a.accepted and not a.applied


def test_concurrent_ingests_into_postgresql_both_land(tmp_path, synth_site, postgres_url) -> None:
    settings = make_home(tmp_path, postgres_url, site_dir=synth_site)
    errors = []

    def run(i: int) -> None:
        cat = open_catalog(settings)
        try:
            ingest_mission(StageContext(cat, settings), epoch_dirs(synth_site)[i], "demo")
        except Exception as exc:  # collected for the assertion below
            errors.append(exc)
        finally:
            cat.dispose()

    threads = [threading.Thread(target=run, args=(i,)) for i in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    cat = open_catalog(settings)
    with cat.transaction() as s:
        assert s.execute(sa.select(sa.func.count(Scene.id))).scalar_one() == 2
        assert s.execute(sa.select(sa.func.count(Pair.id))).scalar_one() == 1
    cat.dispose()
