"""Ingest reads a point cloud once for ingest and tiling: its scan, in parallel point ranges, cuts the
points into tile runs that the tile stage takes over (siteline.pointpass.partition)."""

from __future__ import annotations

import laspy
import numpy as np
import pytest
from sitehelpers import copy_mission, epoch_dirs

from siteline.catalog.context import StageContext
from siteline.errors import RegistrationError
from siteline.ingest.pointcloud import scan_las
from siteline.ingest.stage import ingest_mission
from siteline.pointpass import RECORD, Partition, TilingResources, write_las
from siteline.site.spec import make_site_spec
from siteline.stores import layout
from siteline.synth import LAS_RELPATH
from siteline.tiles.stage import tile_scene


def _kept(settings) -> list[str]:
    home = layout.partitions(settings.home)
    return sorted(p.name for p in home.iterdir()) if home.is_dir() else []


def test_tiling_takes_the_partition_ingest_kept_and_writes_the_same_store(
    cat, site_settings, synth_site
) -> None:
    r = ingest_mission(StageContext(cat, site_settings), epoch_dirs(synth_site)[0], "demo")
    kept = _kept(site_settings)
    assert len(kept) == 1 and not kept[0].startswith(".")
    first = tile_scene(
        StageContext(cat, site_settings), r.scene_id, resources=TilingResources(workers=1)
    ).tiling
    assert first is not None and _kept(site_settings) == []  # claimed and removed
    # a re-tiling finds no partition, cuts the file itself, and writes the very same arrays
    again = tile_scene(
        StageContext(cat, site_settings), r.scene_id, resources=TilingResources(workers=1), retile=True
    ).tiling
    assert again is not None and again.generation == first.generation + 1
    assert again.checksum == first.checksum and again.points == first.points


def test_a_failed_ingest_keeps_no_partition(cat, site_settings, synth_site, tmp_path) -> None:
    ingest_mission(StageContext(cat, site_settings), epoch_dirs(synth_site)[0], "demo")
    kept = _kept(site_settings)
    mission = copy_mission(synth_site, 1, tmp_path)
    las = laspy.read(mission / LAS_RELPATH)
    las.z = np.asarray(las.z) - 10.0  # refused (cannot be co-registered), after the scan
    las.write(mission / LAS_RELPATH)
    with pytest.raises(RegistrationError):
        ingest_mission(StageContext(cat, site_settings), mission, "demo")
    assert _kept(site_settings) == kept


def test_parallel_ranges_scan_and_partition_as_one_process_does(synth_site, tmp_path, monkeypatch) -> None:
    las = epoch_dirs(synth_site)[0] / LAS_RELPATH
    with laspy.open(las) as r:
        origin = (float(r.header.mins[0]) + 20, float(r.header.mins[1]) + 20, float(r.header.mins[2]))
        crs = r.header.parse_crs()
    site = make_site_spec("s", crs.to_string(), origin, None)
    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    one = scan_las(las, site, workers=1, runs_into=tmp_path / "one")
    monkeypatch.setattr("siteline.pointpass.partition.PARALLEL_MIN_POINTS", 1)
    monkeypatch.setattr(
        "siteline.pointpass.partition.RANGE_POINTS", 50_000
    )  # several ranges over two processes
    two = scan_las(las, site, workers=2, runs_into=tmp_path / "two")
    for field in ("point_count", "bounds_min", "bounds_max", "class_histogram", "unknown_codes", "outside_fence",
                  "colour", "gps_time_range"):  # fmt: skip
        assert getattr(one, field) == getattr(two, field), field
    a, b = Partition.load(tmp_path / "one"), Partition.load(tmp_path / "two")
    assert len(b.runs) > len(a.runs) == 1
    pa, pb = a.parts_by_tile(), b.parts_by_tile()
    assert pa.keys() == pb.keys()

    def records(parts: list[tuple[int, str, int, int, int]]) -> np.ndarray:
        return np.concatenate([np.fromfile(p, RECORD, count=c, offset=o * RECORD.itemsize)
                               for _, p, o, c, _ in parts])  # fmt: skip

    for tile in pa:  # the same records per tile, in the same order
        assert records(pa[tile]).tobytes() == records(pb[tile]).tobytes()


def test_the_batch_setting_reaches_the_tile_stage(cat, site_settings, synth_site) -> None:
    from dataclasses import replace

    import pytest
    from sitehelpers import epoch_dirs

    from siteline.config import load_settings
    from siteline.errors import ConfigError
    from siteline.ingest.stage import ingest_mission
    from siteline.tiles.stage import tile_scene

    assert load_settings({"SITELINE_TILE_BATCH_POINTS": "1_000"}).tile_batch_points == 1000
    with pytest.raises(ConfigError, match="SITELINE_TILE_BATCH_POINTS"):
        load_settings({"SITELINE_TILE_BATCH_POINTS": "lots"})
    r = ingest_mission(StageContext(cat, site_settings), epoch_dirs(synth_site)[0], "demo")
    first = tile_scene(
        StageContext(cat, site_settings), r.scene_id, resources=TilingResources(workers=1)
    ).tiling
    small = replace(site_settings, tile_batch_points=2_000)  # every tile in batches
    again = tile_scene(
        StageContext(cat, small), r.scene_id, resources=TilingResources(workers=1), retile=True
    ).tiling
    assert first is not None and again is not None and again.checksum == first.checksum


def test_readers_start_ahead_only_for_a_point_cloud_read_in_parallel(tmp_path, monkeypatch) -> None:
    """start_readers starts the worker pool (ahead of the hashing) when the mission holds a point
    cloud big enough to be read in parallel, and not for a small one or one worker."""
    import siteline.ingest.pointcloud as pc

    started: list[int] = []
    monkeypatch.setattr(pc, "start_pool", started.append)
    rng = np.random.default_rng(0)
    (tmp_path / "lidars").mkdir()
    xyz = rng.uniform(0, 10, (5_000, 3)) + [445_000, 5_030_000, 80]
    write_las(tmp_path / "lidars" / "cloud.las", xyz, crs="EPSG:32618")
    (tmp_path / "broken.laz").write_bytes(b"not a point cloud")
    pc.start_readers(tmp_path, 2)
    assert started == []
    monkeypatch.setattr(pc, "PARALLEL_MIN_POINTS", 5_000)
    pc.start_readers(tmp_path, 1)
    assert started == []
    pc.start_readers(tmp_path, 2)
    assert started == [2]
