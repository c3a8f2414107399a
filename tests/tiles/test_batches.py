"""Tiles written a few blocks at a time (siteline.tiles.batches): the same store whatever the batches,
and a worker's memory set by the batch budget, not by the density."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pyproj

from siteline.pointpass import Slice, TilingResources, write_las
from siteline.records.tiling import TileSpec
from siteline.site.spec import make_site_spec
from siteline.tiles.batches import batches
from siteline.tiles.reader import SceneTiles
from siteline.tiles.writer import TileInput, write_tiles

ORIGIN = (445_000.0, 5_030_000.0, 80.0)


def _surface(path, n: int, seed: int = 0, half_m: float = 25.0) -> None:
    """n points over a 2 half_m square about a gentle surface (the same area at any n)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.01, 2 * half_m - 0.01, (n, 2))
    z = 0.02 * xy[:, 0] + 0.5 * np.sin(xy[:, 1] / 7.0) + rng.normal(0, 0.05, n)
    write_las(
        path, np.c_[xy, z] + np.asarray(ORIGIN), crs="EPSG:32618",
        rgb=rng.integers(0, 256, (n, 3), dtype=np.uint8), classification=np.full(n, 2, np.uint8),
        gps_time=400_000.0 + np.arange(n) * 2e-6,
    )  # fmt: skip


def test_batches_take_whole_blocks_within_the_budget() -> None:
    rows = [(0, "a", 0, 5, 0), (0, "b", 0, 5, 0), (1, "a", 5, 30, 0), (2, "a", 35, 4, 0), (3, "b", 5, 4, 0)]
    parts = [Slice(*r) for r in rows]
    got = batches(parts, 12)
    assert [[p[0] for p in b] for b in got] == [[0, 0], [1], [2, 3]]  # block 1 alone is over budget
    assert batches(parts, 10**9) == [parts]


def test_the_store_is_the_same_whatever_the_batches(tmp_path) -> None:
    _surface(tmp_path / "s.las", 60_000)
    site = make_site_spec("t", "EPSG:32618", ORIGIN)
    spec = TileSpec(node_points=512, chunk_points=4096, shard_points=16_384)
    runs = {}
    for budget in (10**9, 4_000):  # one batch a tile; dozens of batches a tile
        out = tmp_path / f"b{budget}.zarr"
        runs[budget] = write_tiles(
            TileInput(tmp_path / "s.las", site, pyproj.CRS("EPSG:32618")),
            out,
            spec,
            TilingResources(workers=1, batch_points=budget),
        )
    one, many = runs[10**9], runs[4_000]
    assert one.checksum == many.checksum and one.points == many.points == 60_000
    for name, col in one.nodes.columns().items():
        assert np.array_equal(col, many.nodes.columns()[name]), name
    a, b = SceneTiles.open(one.uri), SceneTiles.open(many.uri)
    for tile in a.by_tile:
        pa, pb = a.read_tile(tile, ("gps_time", "rgb")), b.read_tile(tile, ("gps_time", "rgb"))
        assert np.array_equal(pa.xyz_m, pb.xyz_m)
        assert pa.attributes["gps_time"].tobytes() == pb.attributes["gps_time"].tobytes()
    assert not list(tmp_path.glob(".*spill*"))  # no scratch left behind


_WRITE = textwrap.dedent(
    """
    import json, sys
    from pathlib import Path
    from siteline.pointpass import Partition
    from siteline.records.tiling import TileSpec
    from siteline.tiles.batches import write_tile
    from siteline.tiles.layout import tile_key
    import zarr
    folder, out, budget, spec = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3]), TileSpec.from_dict(json.loads(sys.argv[4]))
    def status(field):
        return int(next(l.split()[1] for l in open("/proc/self/status") if l.startswith(field)))
    for k, store in enumerate((out + ".warm", out)):  # the first loads the kernels and zarr
        zarr.open_group(store, mode="w").create_group("tiles")
        if k:  # from here VmHWM is this write's own peak (ru_maxrss keeps the parent's at the fork)
            open("/proc/self/clear_refs", "w").write("5")
            base = status("VmRSS")
        for ij, parts in Partition.load(folder).parts_by_tile().items():
            write_tile(tile_key(*ij), parts, store, spec, 0, str(folder), budget)
    print(base, status("VmHWM"))
    """
)


def _peak_kib(tmp_path, n: int, budget: int) -> tuple[int, int]:
    """RSS before and peak RSS during the tile writing of a process that writes the tiles of n
    points over the same area (partitioned in another process, so only the tile writing counts),
    having written them once before (kernels and libraries loaded)."""
    from siteline.pointpass import PassSource
    from siteline.tiles.writer import _partition

    las, folder = tmp_path / f"s{n}.las", tmp_path / f"p{n}-{budget}"
    if not las.exists():
        _surface(las, n)
    folder.mkdir()
    site = make_site_spec("t", "EPSG:32618", ORIGIN)
    spec = TileSpec(chunk_points=16_384, shard_points=65_536)
    source = PassSource(str(las), site, "EPSG:32618", None, False)
    _partition(source, n, spec, folder, 1, lambda *a: None).save()
    out = subprocess.run(
        [sys.executable, "-c", _WRITE, str(folder), str(tmp_path / f"o{n}-{budget}"), str(budget),
         json.dumps(spec.to_dict())],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    base, peak = out.stdout.split()[-2:]
    return int(base), int(peak)


def test_memory_is_set_by_the_budget_not_the_density(tmp_path) -> None:
    """The same 50 m tile at 4x the density: with a batch budget the writer's peak RSS barely moves;
    without one it grows with the points (so the check can fail)."""
    low = _peak_kib(tmp_path, 300_000, 40_000)
    high = _peak_kib(tmp_path, 1_200_000, 40_000)
    whole = _peak_kib(tmp_path, 1_200_000, 10**9)
    assert high[1] / low[1] <= 1.3, (low, high)
    # what the writing itself takes (the peak above the process's size before it)
    assert (whole[1] - whole[0]) / (high[1] - high[0]) >= 2, (high, whole)


def test_gather_reads_slices_in_order_and_refuses_a_short_run_file(tmp_path) -> None:
    """A batch's slices come back in the parts' order whatever their order in the run files (read
    straight into the records), and a run file shorter than its slices is refused, naming it."""
    import pytest

    from siteline.errors import TileError
    from siteline.pointpass import RECORD
    from siteline.tiles.batches import _gather

    runs = []
    for k in range(2):
        rec = np.zeros(100, RECORD)
        rec["gps_time"] = np.arange(100) + 1000 * k
        path = tmp_path / f"run-{k}.bin"
        rec.tofile(path)
        runs.append(str(path))
    rows = [(0, runs[1], 50, 10, 0), (0, runs[0], 0, 30, 0), (1, runs[0], 30, 5, 0), (1, runs[1], 0, 50, 0)]
    parts = [Slice(*r) for r in rows]
    got = _gather(parts)["gps_time"]
    want = np.r_[1050:1060, 0:30, 30:35, 1000:1050]
    assert np.array_equal(got, want)
    with pytest.raises(TileError, match="run-0.bin ends early"):
        _gather([Slice(0, runs[0], 90, 20, 0)])
