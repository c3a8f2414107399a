"""Every bad mission is refused with an error naming the file and the problem, and leaves nothing
in the catalog or the store."""

from __future__ import annotations

import json
import os
import re
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest
import sqlalchemy as sa
from PIL import Image
from sitehelpers import copy_mission

from siteline.catalog.context import StageContext
from siteline.catalog.models import Camera, Mission, MissionFile, Scene, StageRun
from siteline.errors import (
    CRSError,
    MissionError,
    PhotoError,
    PointCloudError,
    RegistrationError,
    SiteNotFoundError,
)
from siteline.ingest.options import IngestOptions
from siteline.ingest.stage import ingest_mission
from siteline.pointpass import write_las
from siteline.synth import LAS_RELPATH


def _assert_nothing_written(cat, site_settings) -> None:
    with cat.transaction() as s:
        for model in (Mission, MissionFile, Scene, Camera, StageRun):
            assert s.execute(sa.select(sa.func.count()).select_from(model)).scalar_one() == 0, model
    blobs = Path(site_settings.store.url) / "blobs"
    assert not blobs.exists() or not [p for p in blobs.rglob("*") if p.is_file()]


def _raw(mission):
    return next(p for p in mission.iterdir() if p.is_dir() and p.name.startswith("DJI_"))


def _flat_las(path, n=2000, origin=(445000.0, 5030000.0, 80.0), crs="EPSG:32618", scale=0.001):
    rng = np.random.default_rng(0)
    xyz = np.c_[rng.uniform(-30, 30, (n, 2)), rng.normal(0, 0.02, n)] + np.asarray(origin)
    write_las(path, xyz, crs=crs, classification=np.full(n, 2, np.uint8), scale=scale)


def test_empty_folder(cat, site_settings, tmp_path) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(MissionError, match="empty"):
        ingest_mission(StageContext(cat, site_settings), tmp_path / "empty", "demo")
    _assert_nothing_written(cat, site_settings)


def test_missing_folder(cat, site_settings, tmp_path) -> None:
    with pytest.raises(MissionError, match="does not exist"):
        ingest_mission(StageContext(cat, site_settings), tmp_path / "nope", "demo")


def test_no_las(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    shutil.rmtree(mission / "lidars")
    with pytest.raises(MissionError, match="no LAS/LAZ"):
        ingest_mission(StageContext(cat, site_settings), mission, "demo")
    _assert_nothing_written(cat, site_settings)


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_truncated_point_cloud(cat, site_settings, tmp_path, suffix) -> None:
    path = tmp_path / "m" / f"cloud{suffix}"
    _flat_las(path, n=50_000)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(PointCloudError, match=f"cloud{suffix}"):
        ingest_mission(StageContext(cat, site_settings), tmp_path / "m", "demo")
    _assert_nothing_written(cat, site_settings)


def test_corrupt_point_cloud(cat, site_settings, tmp_path) -> None:
    path = tmp_path / "m" / "cloud.laz"
    path.parent.mkdir(parents=True)
    path.write_bytes(b"this is not a LAZ file at all" * 10)
    with pytest.raises(PointCloudError, match="cloud.laz"):
        ingest_mission(StageContext(cat, site_settings), tmp_path / "m", "demo")
    _assert_nothing_written(cat, site_settings)


def test_nan_coordinates(cat, site_settings, tmp_path) -> None:
    path = tmp_path / "m" / "cloud.las"
    _flat_las(path)
    data = bytearray(path.read_bytes())
    data[155:163] = struct.pack("<d", float("nan"))  # the header's x offset
    path.write_bytes(bytes(data))
    with pytest.raises(PointCloudError, match="not finite"):
        ingest_mission(StageContext(cat, site_settings), tmp_path / "m", "demo")
    _assert_nothing_written(cat, site_settings)


def test_absurd_coordinates(cat, site_settings, tmp_path) -> None:
    _flat_las(tmp_path / "m" / "cloud.las", origin=(745000.0, 5030000.0, 80.0))
    with pytest.raises(PointCloudError, match="from the site origin") as err:
        ingest_mission(StageContext(cat, site_settings), tmp_path / "m", "demo")
    # the message names the file and the origin in plain numbers (not numpy reprs)
    assert "cloud.las" in str(err.value) and "np.float64" not in str(err.value)
    assert re.search(r"origin \(\d+\.\d+, \d+\.\d+, -?\d+\.\d+\)", str(err.value))
    _assert_nothing_written(cat, site_settings)


def test_no_crs_and_no_override(cat, site_settings, tmp_path) -> None:
    _flat_las(tmp_path / "m" / "cloud.las", crs=None)
    with pytest.raises(CRSError, match="no CRS.*--crs"):
        ingest_mission(StageContext(cat, site_settings), tmp_path / "m", "demo")
    _assert_nothing_written(cat, site_settings)
    when = __import__("datetime").datetime(2024, 6, 1, tzinfo=__import__("datetime").UTC)
    r = ingest_mission(
        StageContext(cat, site_settings),
        tmp_path / "m",
        "demo",
        IngestOptions(crs="EPSG:32618", captured_at=when),
    )
    assert r.created


def test_untransformable_crs(cat, site_settings, tmp_path) -> None:
    engineering = (
        'ENGCRS["site grid",EDATUM["local"],CS[Cartesian,2],AXIS["x",east,LENGTHUNIT["metre",1]],'
        'AXIS["y",north,LENGTHUNIT["metre",1]]]'
    )
    _flat_las(tmp_path / "m" / "cloud.las", crs=None)
    with pytest.raises(CRSError, match="cloud.las.*site grid"):
        ingest_mission(
            StageContext(cat, site_settings), tmp_path / "m", "demo", IngestOptions(crs=engineering)
        )
    _assert_nothing_written(cat, site_settings)


def test_conflicting_crs_override(cat, site_settings, tmp_path) -> None:
    _flat_las(tmp_path / "m" / "cloud.las")
    with pytest.raises(CRSError, match="--crs"):
        ingest_mission(
            StageContext(cat, site_settings), tmp_path / "m", "demo", IngestOptions(crs="EPSG:32617")
        )
    _assert_nothing_written(cat, site_settings)


def test_photo_without_metadata(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    bad = _raw(mission) / "DJI_20241127000000_9999_D.JPG"
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(bad)
    with pytest.raises(PhotoError, match="DJI_20241127000000_9999_D.JPG.*no usable position"):
        ingest_mission(StageContext(cat, site_settings), mission, "demo")
    _assert_nothing_written(cat, site_settings)


def test_colmap_model_with_too_few_images(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    for photo in sorted(_raw(mission).glob("*.JPG"))[2:]:
        photo.unlink()
    with pytest.raises(RegistrationError, match="only 2 images"):
        ingest_mission(StageContext(cat, site_settings), mission, "demo")
    _assert_nothing_written(cat, site_settings)


def test_colmap_model_with_collinear_positions(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    for photo in sorted(_raw(mission).glob("*.JPG"))[5:]:  # keep the first lawnmower line only
        photo.unlink()
    with pytest.raises(RegistrationError, match="collinear"):
        ingest_mission(StageContext(cat, site_settings), mission, "demo")
    _assert_nothing_written(cat, site_settings)


def test_symlink_outside_the_folder(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    (tmp_path / "secret.txt").write_text("not yours")
    os.symlink("../../secret.txt", mission / "lidars" / "escape.txt")
    with pytest.raises(MissionError, match="escape.txt.*outside"):
        ingest_mission(StageContext(cat, site_settings), mission, "demo")
    _assert_nothing_written(cat, site_settings)


def test_symlink_to_an_absolute_path(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    os.symlink("/etc/hostname", mission / "hostname")
    with pytest.raises(MissionError, match="absolute path"):
        ingest_mission(StageContext(cat, site_settings), mission, "demo")
    _assert_nothing_written(cat, site_settings)


def test_dotdot_names_are_refused() -> None:
    from pathlib import Path

    from siteline.ingest.inventory import check_relative

    with pytest.raises(MissionError, match=r"\.\."):
        check_relative("photos/../../etc/passwd", Path("/m"))
    with pytest.raises(MissionError, match="absolute"):
        check_relative("/etc/passwd", Path("/m"))
    assert str(check_relative("a..b/c.las", Path("/m"))) == "a..b/c.las"


def test_unknown_site(cat, site_settings, synth_site) -> None:
    from sitehelpers import epoch_dirs

    with pytest.raises(SiteNotFoundError, match="nowhere.*demo"):
        ingest_mission(StageContext(cat, site_settings), epoch_dirs(synth_site)[0], "nowhere")
    _assert_nothing_written(cat, site_settings)


def test_two_point_clouds_without_a_preferred_one(cat, site_settings, tmp_path) -> None:
    _flat_las(tmp_path / "m" / "a.las")
    _flat_las(tmp_path / "m" / "b.las")
    with pytest.raises(MissionError, match="several point clouds"):
        ingest_mission(StageContext(cat, site_settings), tmp_path / "m", "demo")
    _assert_nothing_written(cat, site_settings)


def test_failure_after_copy_removes_new_blobs(cat, site_settings, synth_site, tmp_path, monkeypatch) -> None:
    import siteline.ingest.stage as stage_mod

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(stage_mod, "record_ingest", boom)  # the files are stored, the catalog write fails
    from sitehelpers import epoch_dirs

    with pytest.raises(RuntimeError, match="disk full"):
        ingest_mission(StageContext(cat, site_settings), epoch_dirs(synth_site)[0], "demo")
    _assert_nothing_written(cat, site_settings)


def test_las_path_constant_is_where_terra_writes() -> None:
    assert str(LAS_RELPATH) == "lidars/terra_las/cloud_merged.las"


def _count_patched(src: Path, dest: Path, count: int) -> Path:
    """``src`` (LAS 1.2) with its header's point count set to ``count`` (legacy field, byte 107)."""
    data = bytearray(src.read_bytes())
    data[107:111] = struct.pack("<I", count)
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_bytes(bytes(data))
    return dest


@pytest.mark.parametrize(("count", "words"), [(55_000, "header is wrong"), (4_000_000_000, "forged")])
def test_laz_whose_header_count_its_chunks_contradict_is_refused(
    cat, site_settings, tmp_path, count, words
) -> None:
    """A real LAZ (3 chunks of up to 50,000 points) whose header counts half its points would have been
    cut short without a word; one claiming 4e9 points is refused from its chunk table before anything
    is allocated. Ingest (in parallel ranges), and a plain open, refuse both naming the file."""
    import time

    from realdata import AUTZEN

    from siteline.pointpass import open_las

    path = _count_patched(AUTZEN, tmp_path / "m" / "cloud.laz", count)
    t0 = time.perf_counter()
    with pytest.raises(PointCloudError, match=f"cloud.laz.*{words}"):
        open_las(path)
    # refused from the header: reading the claimed points would take minutes (a bound loose enough for a loaded CI machine)
    assert time.perf_counter() - t0 < 30.0
    opts = IngestOptions(
        captured_at=__import__("datetime").datetime(2020, 1, 1, tzinfo=__import__("datetime").UTC),
        crs="EPSG:2994",
    )
    with pytest.raises(PointCloudError, match="LAZ chunks hold 100,001 to 150,000"):
        ingest_mission(StageContext(cat, site_settings), tmp_path / "m", "demo", opts, workers=2)
    _assert_nothing_written(cat, site_settings)
    open_las(_count_patched(AUTZEN, tmp_path / "ok" / "cloud.laz", 110_000)).close()  # the true count


def test_las_whose_header_counts_more_points_than_it_holds_is_refused_at_open(tmp_path) -> None:
    from siteline.pointpass import open_las

    path = tmp_path / "cloud.las"
    _flat_las(path, n=1_000)
    forged = _count_patched(path, tmp_path / "forged.las", 2**31)
    with pytest.raises(PointCloudError, match="forged.las.*truncated"):
        open_las(forged)


def test_non_finite_gps_times_never_reach_the_catalog(db_url, tmp_path) -> None:
    """A LAS holding an infinite and a NaN GPS time ingests on SQLite and PostgreSQL: the scene's
    statistics hold the range of the finite times (JSON has no Infinity), and a failed ingest after
    it still cleans up."""
    import datetime as dt

    from sitehelpers import make_home

    from siteline.catalog import open_catalog
    from siteline.catalog.scenes import scene_statistics

    settings = make_home(tmp_path, url=db_url)
    path = tmp_path / "m" / "cloud.las"
    n = 2000
    rng = np.random.default_rng(0)
    xyz = np.c_[rng.uniform(-30, 30, (n, 2)), rng.normal(0, 0.02, n)] + np.array([445000.0, 5030000.0, 80.0])
    gps = np.linspace(1000.0, 2000.0, n)
    gps[5], gps[9] = np.inf, np.nan
    write_las(path, xyz, crs="EPSG:32618", classification=np.full(n, 2, np.uint8), gps_time=gps)
    cat = open_catalog(settings)
    opts = IngestOptions(captured_at=dt.datetime(2024, 1, 1, tzinfo=dt.UTC))
    r = ingest_mission(StageContext(cat, settings), tmp_path / "m", "demo", opts)
    with cat.transaction() as s:
        scan = scene_statistics(s.get(Scene, r.scene_id)).scan
        raw = s.execute(sa.text("SELECT statistics FROM scene WHERE id = :i"), {"i": r.scene_id}).scalar_one()
    assert scan.gps_time_range == [1000.0, 2000.0]
    assert "Infinity" not in (raw if isinstance(raw, str) else json.dumps(raw))
    cat.dispose()


@pytest.mark.parametrize("short", [2, 500, 9_999])
def test_a_laz_whose_count_is_short_by_less_than_its_last_chunk_is_refused(
    cat, site_settings, tmp_path, short
) -> None:
    """autzen's last chunk holds 10,000 points; a header counting 2 to 9,999 fewer passed the chunk
    table (a fixed-size table records no count per chunk) and lost them without a word. The last
    chunk's bytes decode past the count: refused naming the file, at open and at ingest, nothing
    written."""
    from realdata import AUTZEN

    from siteline.pointpass import open_las

    path = _count_patched(AUTZEN, tmp_path / "m" / "cloud.laz", 110_000 - short)
    with pytest.raises(PointCloudError, match="cloud.laz.*last LAZ chunk holds more than"):
        open_las(path)
    when = __import__("datetime").datetime(2020, 1, 1, tzinfo=__import__("datetime").UTC)
    with pytest.raises(PointCloudError, match="cloud.laz.*last LAZ chunk holds more than"):
        ingest_mission(
            StageContext(cat, site_settings),
            tmp_path / "m",
            "demo",
            IngestOptions(captured_at=when, crs="EPSG:2994"),
            workers=2,
        )
    _assert_nothing_written(cat, site_settings)


def _chunk_size_patched(src: Path, dest: Path, chunk_size: int, count: int | None = None) -> Path:
    """``src`` (LAZ) with its laszip record's chunk size (bytes 12-15 of the record) set, and its header
    count too when given."""
    data = bytearray(src.read_bytes())
    at = (
        data.index(b"laszip encoded") - 2
    )  # the VLR header: reserved (2), user id (16), record id, length, description (32)
    record = at + 54
    data[record + 12 : record + 16] = struct.pack("<I", chunk_size)
    if count is not None:
        data[107:111] = struct.pack("<I", count)
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_bytes(bytes(data))
    return dest


def test_a_forged_laz_chunk_size_is_refused_before_anything_is_allocated(tmp_path) -> None:
    """A chunk size of 2^32 - 2 with a count inside the bound it implies made the decoder ask for
    gigabytes (and print a Rust allocation failure): refused at open, in one line, in well under a
    second, naming the file."""
    import time

    from realdata import AUTZEN

    from siteline.pointpass import open_las

    for count in (None, 2_000_000_000):
        path = _chunk_size_patched(AUTZEN, tmp_path / f"c{count}" / "cloud.laz", 2**32 - 2, count)
        t0 = time.perf_counter()
        with pytest.raises(PointCloudError, match="cloud.laz.*(chunks of 4,294,967,294 points|forged)"):
            open_las(path)
        assert time.perf_counter() - t0 < 30.0  # refused from the chunk table, not by decompressing it
