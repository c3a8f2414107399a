"""Ingest reads a point cloud once for ingest and tiling: its scan, in parallel point ranges, cuts the
points into tile runs that the tile stage takes over (siteline.pointpass.partition)."""

from __future__ import annotations

import os

import laspy
import numpy as np
import pytest
from sitehelpers import copy_mission, epoch_dirs

from siteline.errors import RegistrationError
from siteline.ingest.pointcloud import scan_las
from siteline.ingest.stage import ingest_mission
from siteline.pointpass import TilingResources, partition, schema
from siteline.pointpass.lasio import write_las
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
    r = ingest_mission(cat, site_settings, epoch_dirs(synth_site)[0], "demo")
    kept = _kept(site_settings)
    assert len(kept) == 1 and not kept[0].startswith(".")
    first = tile_scene(cat, site_settings, r.scene_id, resources=TilingResources(workers=1)).tiling
    assert first is not None and _kept(site_settings) == []  # claimed and removed
    # a re-tiling finds no partition, cuts the file itself, and writes the very same arrays
    again = tile_scene(
        cat, site_settings, r.scene_id, resources=TilingResources(workers=1), retile=True
    ).tiling
    assert again is not None and again.generation == first.generation + 1
    assert again.checksum == first.checksum and again.points == first.points


def test_a_failed_ingest_keeps_no_partition(cat, site_settings, synth_site, tmp_path) -> None:
    ingest_mission(cat, site_settings, epoch_dirs(synth_site)[0], "demo")
    kept = _kept(site_settings)
    mission = copy_mission(synth_site, 1, tmp_path)
    las = laspy.read(mission / LAS_RELPATH)
    las.z = np.asarray(las.z) - 10.0  # refused (cannot be co-registered), after the scan
    las.write(mission / LAS_RELPATH)
    with pytest.raises(RegistrationError):
        ingest_mission(cat, site_settings, mission, "demo")
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
    monkeypatch.setattr(partition, "PARALLEL_MIN_POINTS", 1)
    monkeypatch.setattr(partition, "RANGE_POINTS", 50_000)  # several ranges over two processes
    two = scan_las(las, site, workers=2, runs_into=tmp_path / "two")
    for field in ("point_count", "bounds_min", "bounds_max", "class_histogram", "unknown_codes", "outside_fence",
                  "colour", "gps_time_range"):  # fmt: skip
        assert getattr(one, field) == getattr(two, field), field
    a, b = partition.Partition.load(tmp_path / "one"), partition.Partition.load(tmp_path / "two")
    assert len(b.runs) > len(a.runs) == 1
    pa, pb = a.parts_by_tile(), b.parts_by_tile()
    assert pa.keys() == pb.keys()

    def records(parts: list[tuple[int, str, int, int, int]]) -> np.ndarray:
        return np.concatenate([np.fromfile(p, schema.RECORD, count=c, offset=o * schema.RECORD.itemsize)
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
    r = ingest_mission(cat, site_settings, epoch_dirs(synth_site)[0], "demo")
    first = tile_scene(cat, site_settings, r.scene_id, resources=TilingResources(workers=1)).tiling
    small = replace(site_settings, tile_batch_points=2_000)  # every tile in batches
    again = tile_scene(cat, small, r.scene_id, resources=TilingResources(workers=1), retile=True).tiling
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


def test_started_workers_load_the_kernels_as_they_start() -> None:
    """The pool's workers import numba and load a kernel in their initializer, before any task."""
    from siteline.pointpass.workers import process_pool, start_pool

    start_pool(2)
    pool = process_pool(2)
    loaded = [pool.submit(eval, "'numba' in __import__('sys').modules") for _ in range(4)]
    assert all(f.result(timeout=120) for f in loaded)


def test_workers_start_with_one_allocator_arena_and_leave_the_environment_alone(monkeypatch) -> None:
    """Workers spawn with MALLOC_ARENA_MAX=1 (their threads' memory stays on the one heap that keeps
    freed pages); this process's environment is as it was, and a value the user set wins."""
    import os

    from siteline.pointpass import workers

    monkeypatch.delenv("MALLOC_ARENA_MAX", raising=False)
    workers.discard_pool(3)
    try:
        pool = workers.process_pool(3)
        seen = {pool.submit(_worker_env_var).result(timeout=120) for _ in range(6)}
        assert seen == {"1"} and len(pool._processes) == 3  # all three spawned with it
        assert "MALLOC_ARENA_MAX" not in os.environ
        workers.discard_pool(3)
        monkeypatch.setenv("MALLOC_ARENA_MAX", "4")
        assert workers.process_pool(3).submit(_worker_env_var).result(timeout=120) == "4"
        assert os.environ["MALLOC_ARENA_MAX"] == "4"
    finally:
        workers.discard_pool(3)


def _worker_env_var() -> str | None:
    import os

    return os.environ.get("MALLOC_ARENA_MAX")


def _die(k: int) -> int:
    import os

    if k == 1:
        os._exit(9)  # a worker killed under the pass
    return k


def test_a_dead_worker_is_one_clear_error_and_the_next_pass_gets_a_fresh_pool(capsys, monkeypatch) -> None:
    from siteline import cli
    from siteline.errors import WorkerError
    from siteline.pointpass.workers import pool_map, process_pool

    with pytest.raises(WorkerError, match="worker process died.*run the command again"):
        list(pool_map(process_pool(2), _die, range(4)))
    assert list(pool_map(process_pool(2), _die, [0, 2, 3])) == [0, 2, 3]

    def broken(*a, **k):  # noqa: ANN002, ANN003, ANN202
        raise WorkerError("a worker process died (killed, or out of memory)")

    monkeypatch.setattr(cli, "app", broken)
    assert cli.main(["ingest", "x", "--site", "s"]) == 1
    err = capsys.readouterr().err
    assert "worker process died" in err and "Traceback" not in err


KILLED_PARENT = """
import sys, time
from siteline.pointpass.workers import process_pool
pool = process_pool(2)
pids = [pool.submit(__import__("os").getpid).result() for _ in range(4)]
print(" ".join(map(str, sorted(set(pids)))), flush=True)
time.sleep(60)
"""


def test_workers_of_a_killed_parent_exit_within_seconds() -> None:
    """kill -9 of a process holding the pool (an ingest killed mid-partition): its spawned workers,
    re-parented to init, notice within about a second and exit instead of holding their memory."""
    import os
    import signal
    import subprocess
    import sys
    import time

    proc = subprocess.Popen([sys.executable, "-c", KILLED_PARENT], stdout=subprocess.PIPE, text=True)
    try:
        workers = [int(p) for p in proc.stdout.readline().split()]
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert workers

    def alive(pid: int) -> bool:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return True

    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and any(alive(p) for p in workers):
        time.sleep(0.2)
    assert not any(alive(p) for p in workers)


SLOW_START = """
import os, time
if os.environ.get("SITELINE_TEST_SLOW_WORKER_START"):
    time.sleep(4)  # a worker still importing (12-30 s on a loaded machine) when its parent dies
"""
PARENT_OF_SLOW_WORKERS = """
import os, time
os.environ["SITELINE_TEST_SLOW_WORKER_START"] = "1"  # for the workers only: this process has started
from siteline.pointpass.workers import process_pool
process_pool(2)
print(os.getpid(), flush=True)
time.sleep(60)
"""


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                status = open(f"/proc/{entry}/status").read()  # noqa: SIM115
            except OSError:
                continue
            if f"\nPPid:\t{pid}\n" in status:
                out.append(int(entry))
    return out


def test_workers_whose_parent_dies_before_they_start_exit_too(tmp_path) -> None:
    """kill -9 of an ingest while its pool workers are still importing: each worker takes the pid of
    the process that spawned it as an argument, so once it starts it sees that parent gone (a
    worker that read its parent's pid itself would read init's, and live on with the resource
    tracker). Both are gone within seconds."""
    import signal
    import subprocess
    import sys
    import time

    (tmp_path / "sitecustomize.py").write_text(SLOW_START)
    env = os.environ | {"PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", PARENT_OF_SLOW_WORKERS], stdout=subprocess.PIPE, text=True, env=env)
    try:
        parent = int(proc.stdout.readline())
        deadline = time.monotonic() + 10.0
        while len(_children(parent)) < 3 and time.monotonic() < deadline:  # two workers and the resource tracker
            time.sleep(0.1)
        children = _children(parent)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert len(children) >= 2

    def alive(pid: int) -> bool:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return open(f"/proc/{pid}/status").read().find("State:\tZ") < 0

    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and any(alive(p) for p in children):
        time.sleep(0.2)
    assert not any(alive(p) for p in children), [p for p in children if alive(p)]
