"""The tile store: exact round trips at the extremes, LOD partition and uniformity, frustum reads,
crash safety, concurrency, interop and export."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import laspy
import numpy as np
import pyproj
import pytest

from siteline.cameras import Camera
from siteline.lasio import write_las
from siteline.render import RenderSettings, render_points
from siteline.site import make_site_spec
from siteline.tiles import SceneTiles, TileSpec, export_las, write_tiles
from siteline.tiles.layout import level_count, parse_tile_key, tile_origin_local

ALL = ("rgb", "class", "intensity", "gps_time", "return_number")


def _cloud(path: Path, origin, n=20_000, crs="EPSG:32618", scale=0.001, seed=0, extent=120.0):
    rng = np.random.default_rng(seed)
    local = np.c_[rng.uniform(-extent / 2, extent / 2, (n, 2)), rng.uniform(0, 15, n)]
    geo = local + np.asarray(origin)
    write_las(
        path,
        geo,
        crs=crs,
        rgb=rng.integers(0, 256, (n, 3), dtype=np.uint8),
        classification=np.full(n, 2, np.uint8),
        gps_time=np.arange(n, dtype=np.float64),
        scale=scale,
    )
    las = laspy.read(path)
    return np.c_[las.x, las.y, las.z]  # the coordinates as the file holds them


def _tile(tmp_path, las, origin, crs="EPSG:32618", spec=None):
    site = make_site_spec("t", crs, origin)
    result = write_tiles(las, site, pyproj.CRS.from_user_input(crs), tmp_path / "scene.zarr", spec, workers=1)
    return site, result, SceneTiles.open(result.uri)


@pytest.mark.parametrize(
    ("origin", "crs", "scale"),
    [
        ((445_000.0, 5_030_000.0, 80.0), "EPSG:32618", 0.001),
        ((500_000.0, 9_999_000.0, 50.0), "EPSG:32618", 0.001),  # northing near 1e7 m
        ((-8_400_000.0, -4_500_000.0, -30.0), "EPSG:3857", 0.001),  # negative coordinates
        ((445_000.0, 5_030_000.0, 80.0), "EPSG:32618", 1e-4),
        ((445_000.0, 5_030_000.0, 80.0), "EPSG:32618", 1e-7),  # 1e-7 scale: +-214 m around the offset
    ],
)
def test_round_trip_within_half_a_quantum(tmp_path, origin, crs, scale) -> None:
    extent = 100.0 if scale == 1e-7 else 120.0
    geo = _cloud(tmp_path / "c.las", origin, crs=crs, scale=scale, extent=extent)
    site, result, tiles = _tile(tmp_path, tmp_path / "c.las", origin, crs)
    data = tiles.read({t: tiles.prefix(t, None) for t in tiles.by_tile}, ALL)
    ids = data.attributes["gps_time"].astype(np.int64)
    assert np.array_equal(np.sort(ids), np.arange(len(geo)))
    back = data.xyz_m + np.asarray(origin)  # float64 georeferenced
    err = np.abs(back - geo[ids]).max()
    assert err <= 0.5 * tiles.spec.quantum_m + 1e-9


def test_levels_partition_points_and_are_uniform(tmp_path) -> None:
    origin = (445_000.0, 5_030_000.0, 80.0)
    _cloud(tmp_path / "c.las", origin, n=40_000)
    spec = TileSpec(tile_size_m=50.0)
    _, result, tiles = _tile(tmp_path, tmp_path / "c.las", origin, spec=spec)
    assert sum(n.count for n in result.nodes) == result.points == 40_000
    for tile, nodes in tiles.by_tile.items():
        data = tiles.read({tile: tiles.prefix(tile, None)}, ("gps_time",))
        assert len(np.unique(data.attributes["gps_time"])) == len(data.attributes["gps_time"])  # no duplicates
        i, j = parse_tile_key(tile)
        counts = np.rint((data.xyz_m - tile_origin_local(i, j, spec.tile_size_m)) / spec.quantum_m).astype(
            np.int64
        )
        zmin = counts[:, 2].min()
        levels = sorted({n.level for n in nodes})
        ends = {lv: max(n.start + n.count for n in nodes if n.level == lv) for lv in levels}
        for lv in levels:
            # levels 0..lv are a prefix of the tile's arrays
            assert ends[lv] == sum(m.count for m in nodes if m.level <= lv)
            if lv == level_count(spec) - 1:
                continue
            cell = int(round(spec.spacing(lv) / spec.quantum_m))

            def key(c: np.ndarray, cell: int = cell, zmin: int = zmin) -> set:
                return set(map(tuple, np.c_[c[:, 0] // cell, c[:, 1] // cell, (c[:, 2] - zmin) // cell]))

            # every cube of this level's spacing that holds a point holds one of levels <= this one
            assert key(counts[: ends[lv]]) == key(counts)
        # octree nodes: contiguous, disjoint ranges covering the tile, each inside its cube
        ranges = sorted((n.start, n.start + n.count) for n in nodes)
        assert ranges[0][0] == 0 and ranges[-1][1] == len(counts)
        assert all(a[1] == b[0] for a, b in zip(ranges, ranges[1:], strict=False))
        n_tile = int(round(spec.tile_size_m / spec.quantum_m))
        for n in nodes:
            edge = n_tile >> min(n.level, spec.max_node_depth)
            c = counts[n.start : n.start + n.count]
            cube = np.c_[np.clip(c[:, :2] // edge, 0, n_tile // edge - 1), c[:, 2] // edge]
            assert n.cell is not None and (cube == np.array(n.cell)).all()
            lo, hi = np.array(n.bounds_min), np.array(n.bounds_max)
            xyz = data.xyz_m[n.start : n.start + n.count]
            assert (xyz >= lo - 1e-9).all() and (xyz <= hi + 1e-9).all()
    assert max(len(ns) for ns in tiles.by_tile.values()) > level_count(spec)  # levels split into cubes


def test_frustum_read_equals_brute_force(tmp_path) -> None:
    origin = (445_000.0, 5_030_000.0, 80.0)
    geo = _cloud(tmp_path / "c.las", origin, n=30_000)
    _, _, tiles = _tile(tmp_path, tmp_path / "c.las", origin)
    cam = Camera.look_at((-40, -50, 30), (5, 5, 0), 320, 240, fx=200.0)
    got = tiles.points_for_view(cam, 0.5, attributes=("gps_time",), level=None)
    local = geo - np.asarray(origin)
    planes = cam.scaled(0.5).frustum_planes(1e-3)
    brute = np.flatnonzero(np.all(local @ planes[:, :3].T + planes[:, 3] >= 0, axis=1))
    assert set(got.attributes["gps_time"].astype(int)) == set(brute)
    assert got.xyz_m.dtype == np.float64  # xyz_m is float64 site-local metres from every read
    assert got.stats.points_read < 30_000  # culled tiles were not read
    auto = tiles.points_for_view(cam, 0.125, attributes=("gps_time",))
    assert len(auto.xyz_m) < len(got.xyz_m)
    assert set(auto.attributes["gps_time"].astype(int)) <= set(brute)  # a coarser read is a subset
    # per node: near nodes deeper than far ones, so the read is finer than one level for every tile
    chosen, _ = tiles.levels_for_view(cam, 0.125)
    lv = np.concatenate([tiles.node_arrays[t][2][sel] for t, (sel, _) in chosen.items()])
    capped = tiles.points_for_view(cam, 0.125, attributes=("gps_time",), level=int(lv.max()))
    assert len(auto.xyz_m) < len(capped.xyz_m)


def test_points_by_bounds_and_resolution(tmp_path) -> None:
    origin = (445_000.0, 5_030_000.0, 80.0)
    geo = _cloud(tmp_path / "c.las", origin, n=20_000)
    _, _, tiles = _tile(tmp_path, tmp_path / "c.las", origin)
    local = geo - np.asarray(origin)
    got = tiles.points(bounds=(-10, -10, 10, 10), attributes=("gps_time",))
    inside = np.flatnonzero((np.abs(local[:, 0]) <= 10) & (np.abs(local[:, 1]) <= 10))
    assert set(got.attributes["gps_time"].astype(int)) == set(inside)
    coarse = tiles.points(resolution=2.0, attributes=())
    assert 0 < len(coarse.xyz_m) < 20_000
    with pytest.raises(Exception, match="unknown attributes"):
        tiles.points(attributes=("colour",))


def test_export_reads_back_within_the_quantum(tmp_path) -> None:
    origin = (445_000.0, 5_030_000.0, 80.0)
    geo = _cloud(tmp_path / "c.las", origin, n=10_000)
    site, _, tiles = _tile(tmp_path, tmp_path / "c.las", origin)
    n = export_las(tiles, site, tmp_path / "out.laz")
    las = laspy.read(tmp_path / "out.laz")
    assert n == len(las.points) == 10_000
    assert las.header.parse_crs().to_epsg() == 32618
    assert np.abs(las.header.offsets - geo.min(axis=0)).max() < 10.0
    ids = np.asarray(las.gps_time).astype(int)
    assert np.abs(np.c_[las.x, las.y, las.z] - geo[ids]).max() <= 0.001


def test_interop_with_tensorstore(tmp_path) -> None:
    import tensorstore as ts
    import zarr

    origin = (445_000.0, 5_030_000.0, 80.0)
    _cloud(tmp_path / "c.las", origin, n=5_000)
    _, result, tiles = _tile(tmp_path, tmp_path / "c.las", origin)
    for tile in tiles.by_tile:
        for name in ("xyz_counts", "class"):
            path = os.path.join(result.uri, "tiles", tile, name)
            theirs = (
                ts.open({"driver": "zarr3", "kvstore": {"driver": "file", "path": path}})
                .result()
                .read()
                .result()
            )
            ours = zarr.open_array(path, mode="r")[...]
            assert np.array_equal(theirs, ours)


def test_existing_store_is_not_overwritten(tmp_path) -> None:
    origin = (445_000.0, 5_030_000.0, 80.0)
    _cloud(tmp_path / "c.las", origin, n=1_000)
    site, result, _ = _tile(tmp_path, tmp_path / "c.las", origin)
    with pytest.raises(Exception, match="already exists"):
        write_tiles(tmp_path / "c.las", site, pyproj.CRS("EPSG:32618"), Path(result.uri), workers=1)


KILL_SCRIPT = textwrap.dedent("""
    import os, signal, sys
    import siteline.tiles.writer as w
    from siteline.catalog import open_catalog
    from siteline.config import load_settings
    from siteline.tiles import tile_scene
    real = w.write_tile
    done = []
    def dying(*a, **k):
        if len(done) == 2:
            os.kill(os.getpid(), signal.SIGKILL)
        done.append(1)
        return real(*a, **k)
    w.write_tile = dying
    settings = load_settings()
    tile_scene(open_catalog(settings), settings, int(sys.argv[1]), workers=1)
""")


def _ingested_home(tmp_path, synth_dir, name):
    from sitehelpers import epoch_dirs, make_home

    from siteline.catalog import open_catalog
    from siteline.ingest import ingest_mission

    settings = make_home(tmp_path / name, site_dir=synth_dir)
    cat = open_catalog(settings)
    ids = [ingest_mission(cat, settings, m, "demo").scene_id for m in epoch_dirs(synth_dir)[:2]]
    cat.dispose()
    return settings, ids


@pytest.fixture(scope="module")
def synth_dir(tmp_path_factory):
    from siteline.synth import SynthConfig, write_site

    out = tmp_path_factory.mktemp("synth-tiles")
    write_site(out, SynthConfig(epochs=2, density_pts_m2=2.0, seed=8, photos=False, colmap=False))
    return out


def _env(settings):
    return {**os.environ, "SITELINE_HOME": str(settings.home), "SITELINE_DATABASE_URL": settings.database_url}


def test_killed_writer_leaves_nothing_and_rerun_matches(tmp_path, synth_dir) -> None:
    import sqlalchemy as sa

    from siteline.catalog import open_catalog
    from siteline.catalog.models import Node, Scene
    from siteline.tiles import tile_scene

    settings, (sid, _) = _ingested_home(tmp_path, synth_dir, "a")
    proc = subprocess.run(
        [sys.executable, "-c", KILL_SCRIPT, str(sid)], env=_env(settings), capture_output=True
    )
    assert proc.returncode == -9, proc.stderr.decode()[-2000:]
    tiles_dir = Path(settings.store.url) / "tiles"
    assert not (tiles_dir / f"scene-{sid}.zarr").exists()
    cat = open_catalog(settings)
    with cat.transaction() as s:
        assert s.execute(sa.select(sa.func.count(Node.id))).scalar_one() == 0
        assert s.get(Scene, sid).status == "registered"
    rerun = tile_scene(cat, settings, sid, workers=1).tiling
    assert not [p for p in tiles_dir.iterdir() if p.name.startswith(".")]  # stale partials were cleared
    cat.dispose()
    clean_settings, (sid2, _) = _ingested_home(tmp_path, synth_dir, "b")
    cat2 = open_catalog(clean_settings)
    clean = tile_scene(cat2, clean_settings, sid2, workers=1).tiling
    cat2.dispose()
    assert rerun.checksum == clean.checksum and rerun.points == clean.points


def test_two_processes_tile_two_scenes_at_once(tmp_path, synth_dir) -> None:
    import sqlalchemy as sa

    from siteline.catalog import open_catalog
    from siteline.catalog.models import Node, Scene

    settings, ids = _ingested_home(tmp_path, synth_dir, "c")
    code = (
        "import sys\nfrom siteline.catalog import open_catalog\nfrom siteline.config import load_settings\n"
        "from siteline.tiles import tile_scene\ns = load_settings()\ntile_scene(open_catalog(s), s, int(sys.argv[1]), workers=1)\n"
    )
    procs = [subprocess.Popen([sys.executable, "-c", code, str(i)], env=_env(settings)) for i in ids]
    assert [p.wait(timeout=300) for p in procs] == [0, 0]
    cat = open_catalog(settings)
    with cat.transaction() as s:
        for i in ids:
            scene = s.get(Scene, i)
            assert scene.status == "tiled"
            total = s.execute(sa.select(sa.func.sum(Node.point_count)).where(Node.scene_id == i)).scalar_one()
            assert total == scene.point_count
            assert SceneTiles.open(scene.tile_store_uri).point_count == scene.point_count
    cat.dispose()


def test_stores_with_whole_level_nodes_still_read(tmp_path) -> None:
    """A store written before octree nodes indexes one node per tile level (no cube), keeps input
    order inside a node and calls its int32 counts ``xyz``: every read still works, with per-tile
    culling and whole nodes."""
    from siteline.records import NodeInfo
    from siteline.tiles.reader import SceneTiles

    origin = (445_000.0, 5_030_000.0, 80.0)
    geo = _cloud(tmp_path / "c.las", origin, n=20_000)
    _, result, tiles = _tile(tmp_path, tmp_path / "c.las", origin)
    for tile in tiles.by_tile:
        os.rename(Path(result.uri, "tiles", tile, "xyz_counts"), Path(result.uri, "tiles", tile, "xyz"))
    merged = []
    for tile, nodes in tiles.by_tile.items():
        for lv in sorted({n.level for n in nodes}):
            ns = [n for n in nodes if n.level == lv]
            merged.append(
                NodeInfo(
                    f"{tile}/{lv}", tile, lv,
                    tuple(np.min([n.bounds_min for n in ns], axis=0)), tuple(np.max([n.bounds_max for n in ns], axis=0)),
                    sum(n.count for n in ns), min(n.start for n in ns), ns[0].spacing_m,
                )
            )  # fmt: skip
    assert (
        TileSpec.from_dict({k: v for k, v in tiles.spec.to_dict().items() if k != "node_order"}).node_order
        == "input"
    )
    old = SceneTiles(tiles.uri, merged, dataclasses.replace(tiles.spec, node_order="input"))
    cam = Camera.look_at((-40, -50, 30), (5, 5, 0), 320, 240, fx=200.0)
    local = geo - np.asarray(origin)
    planes = cam.scaled(0.5).frustum_planes(1e-3)
    brute = np.flatnonzero(np.all(local @ planes[:, :3].T + planes[:, 3] >= 0, axis=1))
    got = old.points_for_view(cam, 0.5, attributes=("gps_time",), level=None)
    assert set(got.attributes["gps_time"].astype(int)) == set(brute)
    auto = old.points_for_view(cam, 0.125, attributes=("gps_time",))
    assert 0 < len(auto.xyz_m) and set(auto.attributes["gps_time"].astype(int)) <= set(brute)
    chosen, _ = old.levels_for_view(cam, 0.125)  # input order: whole nodes only, never a part
    assert all(np.array_equal(take, old.node_arrays[t][4][sel]) for t, (sel, take) in chosen.items())


def test_partial_levels_read_what_the_footprint_needs(tmp_path) -> None:
    """Shuffled nodes: a node's prefix is spread over the whole node, and a nadir view over a dense
    surface reads about one point per drawn half point, at the coverage of reading everything."""
    origin = (445_000.0, 5_030_000.0, 80.0)
    rng = np.random.default_rng(3)
    n = 358_400  # 100 points/m2 over 64 x 56 m
    local = np.c_[rng.uniform(-32, 32, n), rng.uniform(-28, 28, n), rng.normal(0, 0.02, n)]
    write_las(
        tmp_path / "p.las",
        local + np.asarray(origin),
        crs="EPSG:32618",
        classification=np.full(n, 2, np.uint8),
    )
    _, _, tiles = _tile(tmp_path, tmp_path / "p.las", origin)
    assert tiles.spec.node_order == "random"
    tile = max(tiles.by_tile, key=lambda t: tiles.prefix(t))
    node = max(tiles.by_tile[tile], key=lambda nd: nd.count)
    xyz = tiles.read_nodes(
        {tile: (np.array([tiles.by_tile[tile].index(node)]), np.array([node.count // 10]))}, ()
    ).xyz_m
    span = (xyz.max(axis=0) - xyz.min(axis=0))[:2] / (np.array(node.bounds_max) - node.bounds_min)[:2]
    assert np.all(span > 0.9), span  # the first tenth spans the node, not a corner of it
    cam = Camera.look_at((0, 0, 40), (0, 0, 0), 150, 125, fx=100.0)  # 0.4 m pixels over 0.1 m data
    every = tiles.points_for_view(cam, 1.0, level=None)
    for size, most in ((1, 6.0), (3, 0.8)):
        settings = RenderSettings(scale=1.0, point_size_px=size)
        full = render_points(every.xyz_m.astype(np.float32), cam, settings)
        pts = tiles.points_for_view(cam, 1.0, point_size_px=size)
        img = render_points(pts.xyz_m.astype(np.float32), cam, settings)
        per_pixel = pts.stats.points_read / img.hit.sum()
        assert per_pixel < most and per_pixel < len(every.xyz_m) / full.hit.sum() / 2.5, (size, per_pixel)
        assert img.coverage >= full.coverage - 0.01, (size, img.coverage, full.coverage)
    coarse = tiles.points_for_view(cam, 1.0, point_size_px=3, lod_factor=2.0)
    assert len(coarse.xyz_m) < 0.4 * len(pts.xyz_m)  # the read follows the factor continuously


def test_reads_decode_only_the_chunks_they_touch(tmp_path) -> None:
    """A node read decodes the inner chunks its points lie in, not the tile's prefix; a repeat comes
    from the cache; a cache too small for the read still returns the right values."""
    origin = (445_000.0, 5_030_000.0, 80.0)
    _cloud(tmp_path / "c.las", origin, n=40_000, extent=40.0)
    spec = TileSpec(chunk_points=1024, shard_points=8192)
    _, result, tiles = _tile(tmp_path, tmp_path / "c.las", origin, spec=spec)
    tile = max(tiles.by_tile, key=tiles.prefix)
    whole = tiles.read({tile: tiles.prefix(tile)}, ("gps_time",))
    last = len(tiles.by_tile[tile]) - 1  # the deepest node: at the end of the arrays
    node = tiles.by_tile[tile][last]
    for cache in (256 * 2**20, 4096):
        fresh = SceneTiles(result.uri, tiles.nodes, tiles.spec, cache_bytes=cache)
        got = fresh.read_nodes({tile: (np.array([last]), np.array([node.count]))}, ("gps_time",))
        want = slice(node.start, node.start + node.count)
        assert np.array_equal(got.attributes["gps_time"], whole.attributes["gps_time"][want])
        assert np.array_equal(got.xyz_m, whole.xyz_m[want])
        first, end = node.start // 1024, -(-(node.start + node.count) // 1024)
        assert got.stats.points_decoded <= 2 * (end - first) * 1024 < tiles.prefix(tile)
        again = fresh.read_nodes({tile: (np.array([last]), np.array([node.count]))}, ("gps_time",))
        assert (again.stats.points_decoded == 0) == (cache > 4096)
