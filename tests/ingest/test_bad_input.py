"""Every bad mission is refused with an error naming the file and the problem, and leaves nothing
in the catalog or the store."""

from __future__ import annotations

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

from siteline.catalog.models import Camera, Mission, MissionFile, Scene, StageRun
from siteline.errors import (
    CRSError,
    MissionError,
    PhotoError,
    PointCloudError,
    RegistrationError,
    SiteNotFoundError,
)
from siteline.ingest import IngestOptions, ingest_mission
from siteline.lasio import write_las
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
        ingest_mission(cat, site_settings, tmp_path / "empty", "demo")
    _assert_nothing_written(cat, site_settings)


def test_missing_folder(cat, site_settings, tmp_path) -> None:
    with pytest.raises(MissionError, match="does not exist"):
        ingest_mission(cat, site_settings, tmp_path / "nope", "demo")


def test_no_las(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    shutil.rmtree(mission / "lidars")
    with pytest.raises(MissionError, match="no LAS/LAZ"):
        ingest_mission(cat, site_settings, mission, "demo")
    _assert_nothing_written(cat, site_settings)


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_truncated_point_cloud(cat, site_settings, tmp_path, suffix) -> None:
    path = tmp_path / "m" / f"cloud{suffix}"
    _flat_las(path, n=50_000)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(PointCloudError, match=f"cloud{suffix}"):
        ingest_mission(cat, site_settings, tmp_path / "m", "demo")
    _assert_nothing_written(cat, site_settings)


def test_corrupt_point_cloud(cat, site_settings, tmp_path) -> None:
    path = tmp_path / "m" / "cloud.laz"
    path.parent.mkdir(parents=True)
    path.write_bytes(b"this is not a LAZ file at all" * 10)
    with pytest.raises(PointCloudError, match="cloud.laz"):
        ingest_mission(cat, site_settings, tmp_path / "m", "demo")
    _assert_nothing_written(cat, site_settings)


def test_nan_coordinates(cat, site_settings, tmp_path) -> None:
    path = tmp_path / "m" / "cloud.las"
    _flat_las(path)
    data = bytearray(path.read_bytes())
    data[155:163] = struct.pack("<d", float("nan"))  # the header's x offset
    path.write_bytes(bytes(data))
    with pytest.raises(PointCloudError, match="not finite"):
        ingest_mission(cat, site_settings, tmp_path / "m", "demo")
    _assert_nothing_written(cat, site_settings)


def test_absurd_coordinates(cat, site_settings, tmp_path) -> None:
    _flat_las(tmp_path / "m" / "cloud.las", origin=(745000.0, 5030000.0, 80.0))
    with pytest.raises(PointCloudError, match="from the site origin") as err:
        ingest_mission(cat, site_settings, tmp_path / "m", "demo")
    # the message names the file and the origin in plain numbers (not numpy reprs)
    assert "cloud.las" in str(err.value) and "np.float64" not in str(err.value)
    assert re.search(r"origin \(\d+\.\d+, \d+\.\d+, -?\d+\.\d+\)", str(err.value))
    _assert_nothing_written(cat, site_settings)


def test_no_crs_and_no_override(cat, site_settings, tmp_path) -> None:
    _flat_las(tmp_path / "m" / "cloud.las", crs=None)
    with pytest.raises(CRSError, match="no CRS.*--crs"):
        ingest_mission(cat, site_settings, tmp_path / "m", "demo")
    _assert_nothing_written(cat, site_settings)
    r = ingest_mission(cat, site_settings, tmp_path / "m", "demo", IngestOptions(crs="EPSG:32618"))
    assert r.created


def test_untransformable_crs(cat, site_settings, tmp_path) -> None:
    engineering = (
        'ENGCRS["site grid",EDATUM["local"],CS[Cartesian,2],AXIS["x",east,LENGTHUNIT["metre",1]],'
        'AXIS["y",north,LENGTHUNIT["metre",1]]]'
    )
    _flat_las(tmp_path / "m" / "cloud.las", crs=None)
    with pytest.raises(CRSError, match="cloud.las.*site grid"):
        ingest_mission(cat, site_settings, tmp_path / "m", "demo", IngestOptions(crs=engineering))
    _assert_nothing_written(cat, site_settings)


def test_conflicting_crs_override(cat, site_settings, tmp_path) -> None:
    _flat_las(tmp_path / "m" / "cloud.las")
    with pytest.raises(CRSError, match="--crs"):
        ingest_mission(cat, site_settings, tmp_path / "m", "demo", IngestOptions(crs="EPSG:32617"))
    _assert_nothing_written(cat, site_settings)


def test_photo_without_metadata(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    bad = _raw(mission) / "DJI_20241127000000_9999_D.JPG"
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(bad)
    with pytest.raises(PhotoError, match="DJI_20241127000000_9999_D.JPG.*no usable position"):
        ingest_mission(cat, site_settings, mission, "demo")
    _assert_nothing_written(cat, site_settings)


def test_colmap_model_with_too_few_images(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    for photo in sorted(_raw(mission).glob("*.JPG"))[2:]:
        photo.unlink()
    with pytest.raises(RegistrationError, match="only 2 images"):
        ingest_mission(cat, site_settings, mission, "demo")
    _assert_nothing_written(cat, site_settings)


def test_colmap_model_with_collinear_positions(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    for photo in sorted(_raw(mission).glob("*.JPG"))[5:]:  # keep the first lawnmower line only
        photo.unlink()
    with pytest.raises(RegistrationError, match="collinear"):
        ingest_mission(cat, site_settings, mission, "demo")
    _assert_nothing_written(cat, site_settings)


def test_symlink_outside_the_folder(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    (tmp_path / "secret.txt").write_text("not yours")
    os.symlink("../../secret.txt", mission / "lidars" / "escape.txt")
    with pytest.raises(MissionError, match="escape.txt.*outside"):
        ingest_mission(cat, site_settings, mission, "demo")
    _assert_nothing_written(cat, site_settings)


def test_symlink_to_an_absolute_path(cat, site_settings, synth_site, tmp_path) -> None:
    mission = copy_mission(synth_site, 0, tmp_path)
    os.symlink("/etc/hostname", mission / "hostname")
    with pytest.raises(MissionError, match="absolute path"):
        ingest_mission(cat, site_settings, mission, "demo")
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
        ingest_mission(cat, site_settings, epoch_dirs(synth_site)[0], "nowhere")
    _assert_nothing_written(cat, site_settings)


def test_two_point_clouds_without_a_preferred_one(cat, site_settings, tmp_path) -> None:
    _flat_las(tmp_path / "m" / "a.las")
    _flat_las(tmp_path / "m" / "b.las")
    with pytest.raises(MissionError, match="several point clouds"):
        ingest_mission(cat, site_settings, tmp_path / "m", "demo")
    _assert_nothing_written(cat, site_settings)


def test_failure_after_copy_removes_new_blobs(cat, site_settings, synth_site, tmp_path, monkeypatch) -> None:
    import siteline.ingest.stage as stage_mod

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(stage_mod, "record_ingest", boom)  # the files are stored, the catalog write fails
    from sitehelpers import epoch_dirs

    with pytest.raises(RuntimeError, match="disk full"):
        ingest_mission(cat, site_settings, epoch_dirs(synth_site)[0], "demo")
    _assert_nothing_written(cat, site_settings)


def test_las_path_constant_is_where_terra_writes() -> None:
    assert str(LAS_RELPATH) == "lidars/terra_las/cloud_merged.las"
