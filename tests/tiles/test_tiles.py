"""The tile store: exact round trips at the extremes, LOD partition and uniformity, frustum reads,
crash safety, concurrency, interop and export."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import laspy
import numpy as np
import pyproj
import pytest

from siteline.camera.pinhole import Camera
from siteline.catalog.context import StageContext
from siteline.errors import TileError
from siteline.pointpass import TilingResources, write_las
from siteline.records.params.render import RenderParams
from siteline.records.tiling import TileSpec
from siteline.render.zbuffer import render_points
from siteline.site.spec import make_site_spec
from siteline.tiles.export import export_las
from siteline.tiles.layout import parse_tile_key, tile_origin_local
from siteline.tiles.reader import SceneTiles, boxes_inside_frustum
from siteline.tiles.writer import TileInput, write_tiles

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
    result = write_tiles(
        TileInput(las, site, pyproj.CRS.from_user_input(crs)),
        tmp_path / "scene.zarr",
        spec,
        TilingResources(workers=1),
    )
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
    data = tiles.read({t: tiles.prefix(t) for t in tiles.by_tile}, ALL)
    ids = data.attributes["gps_time"].astype(np.int64)
    assert np.array_equal(np.sort(ids), np.arange(len(geo)))
    back = data.xyz_m + np.asarray(origin)  # float64 georeferenced
    err = np.abs(back - geo[ids]).max()
    assert err <= 0.5 * tiles.spec.quantum_m + 1e-9


def test_a_tile_read_in_float32_blocks_is_the_read_cast(tmp_path) -> None:
    """read_tile_uncached (the labels' read: block by block, past the cache) gives read_tile's values
    cast to float32, georeferenced, with blocks smaller than a tile, and names an unknown attribute."""
    origin = (445_000.0, 5_030_000.0, 80.0)
    _cloud(tmp_path / "c.las", origin, n=30_000)
    _, _, tiles = _tile(
        tmp_path,
        tmp_path / "c.las",
        origin,
        spec=TileSpec(tile_size_m=60.0, chunk_points=1024, shard_points=4096),
    )
    for tile in tiles.by_tile:
        whole = tiles.read_tile(tile, ("class", "gps_time"))
        cached = tiles._cached
        xyz, attrs = tiles.read_tile_uncached(tile, ("class", "gps_time"), block_points=5000)
        assert tiles._cached == cached  # past the cache
        assert xyz.dtype == np.float32 and np.array_equal(xyz, whole.xyz_m.astype(np.float32))
        assert all(np.array_equal(attrs[a], whole.attributes[a]) for a in ("class", "gps_time"))
    with pytest.raises(TileError, match="unknown attributes"):
        tiles.read_tile_uncached(next(iter(tiles.by_tile)), ("colour",))


def test_levels_partition_points_and_are_uniform(tmp_path) -> None:
    origin = (445_000.0, 5_030_000.0, 80.0)
    _cloud(tmp_path / "c.las", origin, n=40_000)
    spec = TileSpec(tile_size_m=50.0, node_points=256)  # small nodes: bands cut into cubes at this size
    _, result, tiles = _tile(tmp_path, tmp_path / "c.las", origin, spec=spec)
    assert result.nodes.points == result.points == 40_000 and tiles.point_count == 40_000
    last_level = spec.level_count - 1
    for tile, nodes in tiles.by_tile.items():
        data = tiles.read({tile: tiles.prefix(tile)}, ("gps_time",))
        assert len(np.unique(data.attributes["gps_time"])) == len(
            data.attributes["gps_time"]
        )  # no duplicates
        i, j = parse_tile_key(tile)
        counts = np.rint((data.xyz_m - tile_origin_local(i, j, spec.tile_size_m)) / spec.quantum_m).astype(
            np.int64
        )
        zmin = counts[:, 2].min()
        # nodes: contiguous, disjoint ranges covering the tile, each inside its bounds
        assert nodes.start[0] == 0 and nodes.start[-1] + nodes.count[-1] == len(counts)
        assert np.array_equal(nodes.start[1:], (nodes.start + nodes.count)[:-1])
        for k in range(len(nodes)):
            xyz = data.xyz_m[nodes.start[k] : nodes.start[k] + nodes.count[k]]
            assert (xyz >= nodes.lo[k] - 1e-9).all() and (xyz <= nodes.hi[k] + 1e-9).all()
        for lv in range(last_level):
            # the points of levels <= lv, read node by node, hold a point in every occupied cube of
            # this level's spacing (each level is a uniform subsample)
            upto = tiles.read_tile(tile, ("gps_time",), level=lv)
            assert len(upto) == int(nodes.up_to(lv).sum())
            cell = int(round(spec.spacing(lv) / spec.quantum_m))
            c = np.rint((upto.xyz_m - tile_origin_local(i, j, spec.tile_size_m)) / spec.quantum_m).astype(
                np.int64
            )

            def key(c: np.ndarray, cell: int = cell, zmin: int = zmin) -> set:
                return set(map(tuple, np.c_[c[:, 0] // cell, c[:, 1] // cell, (c[:, 2] - zmin) // cell]))

            assert key(c) == key(counts)
            # a node's points of levels <= lv are its first ones (levels sorted inside a node)
            first = np.concatenate(
                [np.arange(s0, s0 + k) for s0, k in zip(nodes.start, nodes.up_to(lv), strict=True)]
            )
            assert set(upto.attributes["gps_time"]) == set(data.attributes["gps_time"][first])
    # every node but a tile's sparse remainder holds node_points; bands cut into cubes where dense
    rows = tiles.nodes
    assert len(rows) <= result.points / 200
    assert int((rows.depth > 0).sum()) > 0 and int((rows.level > rows.first_level).sum()) > 0


def test_node_index_grows_with_points_not_levels(tmp_path) -> None:
    """At the default node size, a scene's node rows are at most points / 2,000, the index lives in
    the store (no JSON node list in its attributes), and a view reads no more points than with small
    nodes."""
    import json

    origin = (445_000.0, 5_030_000.0, 80.0)
    rng = np.random.default_rng(1)
    n = 400_000  # 400 points/m2 over 40 x 25 m: a dense surface
    local = np.c_[rng.uniform(-20, 20, n), rng.uniform(-12.5, 12.5, n), rng.normal(0, 0.05, n)]
    write_las(
        tmp_path / "d.las",
        local + np.asarray(origin),
        crs="EPSG:32618",
        classification=np.full(n, 2, np.uint8),
    )
    _, result, tiles = _tile(tmp_path, tmp_path / "d.las", origin)
    assert len(result.nodes) <= n / 2000, len(result.nodes)
    attrs = json.loads((Path(result.uri) / "zarr.json").read_text())["attributes"]
    assert "nodes" not in attrs and attrs["siteline_tiles"] == 2
    small = tmp_path / "small"
    small.mkdir()
    _, r2, fine = _tile(small, tmp_path / "d.las", origin, spec=TileSpec(node_points=64))
    assert len(r2.nodes) > 4 * len(result.nodes)
    cam = Camera.look_at((0, -15, 12), (0, 0, 0), 200, 150, fx=150.0)
    big_read = tiles.points_for_view(cam, 1.0, attributes=())
    small_read = fine.points_for_view(cam, 1.0, attributes=())
    # coarser culling reads more candidates, but not more than twice: fine levels stay in cubes
    assert big_read.stats.points_read <= 2 * small_read.stats.points_read
    assert abs(len(big_read) - len(small_read)) <= 0.25 * len(small_read)


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
    # ... though only the points of nodes that cross a plane were tested (both kinds are here)
    full = tiles._frustum_nodes(cam, 0.5, None, 1e-3)
    inside = np.concatenate(
        [
            boxes_inside_frustum(full.planes, tiles.by_tile[t].lo[s], tiles.by_tile[t].hi[s])
            for t, (s, _) in full.selection.items()
        ]
    )
    assert inside.any() and (~inside).any()
    assert got.xyz_m.dtype == np.float64  # xyz_m is float64 site-local metres from every read
    assert got.stats.points_read < 30_000  # culled tiles were not read
    auto = tiles.points_for_view(cam, 0.125, attributes=("gps_time",))
    assert len(auto.xyz_m) < len(got.xyz_m)
    assert set(auto.attributes["gps_time"].astype(int)) <= set(brute)  # a coarser read is a subset
    # per node: near nodes deeper than far ones, so the read is finer than one level for every tile
    chosen = tiles.levels_for_view(cam, 0.125).selection
    deepest = max(tiles.read_nodes(chosen, ()).stats.levels.values())
    capped = tiles.points_for_view(cam, 0.125, attributes=("gps_time",), level=deepest)
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
        # every array but gps_time, whose fixed scale/offset filter is numcodecs' (zarr-python)
        for name in ("xyz_counts", "rgb", "intensity", "class", "return_number"):
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
        write_tiles(
            TileInput(tmp_path / "c.las", site, pyproj.CRS("EPSG:32618")),
            Path(result.uri),
            resources=TilingResources(workers=1),
        )


def test_counts_past_int32_are_refused_naming_the_file(tmp_path) -> None:
    # a micrometre quantum: 15 m of z is 1.5e7 counts, fine; 3 km overflows int32 (2.1 km)
    origin = (445_000.0, 5_030_000.0, 80.0)
    _cloud(tmp_path / "c.las", origin, n=1_000)
    xyz = _cloud(tmp_path / "far.las", origin, n=1_000)
    xyz[5, 2] = origin[2] + 3_000.0
    write_las(tmp_path / "far.las", xyz, crs="EPSG:32618")
    spec = TileSpec(quantum_m=1e-6)
    with pytest.raises(TileError, match=r"far\.las: a point lies 3,000 m .* quantum"):
        _tile(tmp_path, tmp_path / "far.las", origin, spec=spec)
    assert not (tmp_path / "scene.zarr").exists()
    assert _tile(tmp_path, tmp_path / "c.las", origin, spec=spec)[1].points == 1_000


KILL_SCRIPT = textwrap.dedent("""
    import os, signal, sys
    import siteline.tiles.writer as w
    from siteline.catalog import open_catalog
    from siteline.config import load_settings
    from siteline.pointpass import TilingResources
    from siteline.catalog.context import StageContext
    from siteline.tiles.stage import tile_scene
    real = w.write_tile
    done = []
    def dying(*a, **k):
        if len(done) == 2:
            os.kill(os.getpid(), signal.SIGKILL)
        done.append(1)
        return real(*a, **k)
    w.write_tile = dying
    settings = load_settings()
    tile_scene(StageContext(open_catalog(settings), settings), int(sys.argv[1]), resources=TilingResources(workers=1))
""")


def _ingested_home(tmp_path, synth_dir, name):
    from sitehelpers import epoch_dirs, make_home

    from siteline.catalog import open_catalog
    from siteline.ingest.stage import ingest_mission

    settings = make_home(tmp_path / name, site_dir=synth_dir)
    cat = open_catalog(settings)
    ids = [ingest_mission(StageContext(cat, settings), m, "demo").scene_id for m in epoch_dirs(synth_dir)[:2]]
    cat.dispose()
    return settings, ids


@pytest.fixture(scope="module")
def synth_dir(tmp_path_factory):
    from siteline.synth import SynthParams, write_site

    out = tmp_path_factory.mktemp("synth-tiles")
    write_site(out, SynthParams(epochs=2, density_pts_m2=2.0, seed=8, photos=False, colmap=False))
    return out


def _env(settings):
    return {**os.environ, "SITELINE_HOME": str(settings.home), "SITELINE_DATABASE_URL": settings.database_url}


def test_killed_writer_leaves_nothing_and_rerun_matches(tmp_path, synth_dir) -> None:
    from siteline.catalog import open_catalog
    from siteline.catalog.models import Scene
    from siteline.tiles.stage import tile_scene

    settings, (sid, _) = _ingested_home(tmp_path, synth_dir, "a")
    proc = subprocess.run(
        [sys.executable, "-c", KILL_SCRIPT, str(sid)], env=_env(settings), capture_output=True
    )
    assert proc.returncode == -9, proc.stderr.decode()[-2000:]
    tiles_dir = Path(settings.store.url) / "tiles"
    assert not (tiles_dir / f"scene-{sid}.zarr").exists()
    cat = open_catalog(settings)
    with cat.transaction() as s:
        assert s.get(Scene, sid).status == "registered" and s.get(Scene, sid).tile_store_uri is None
    rerun = tile_scene(StageContext(cat, settings), sid, resources=TilingResources(workers=1)).tiling
    assert not [p for p in tiles_dir.iterdir() if p.name.startswith(".")]  # stale partials were cleared
    cat.dispose()
    clean_settings, (sid2, _) = _ingested_home(tmp_path, synth_dir, "b")
    cat2 = open_catalog(clean_settings)
    clean = tile_scene(StageContext(cat2, clean_settings), sid2, resources=TilingResources(workers=1)).tiling
    cat2.dispose()
    assert rerun.checksum == clean.checksum and rerun.points == clean.points


def test_two_processes_tile_two_scenes_at_once(tmp_path, synth_dir) -> None:
    from siteline.catalog import open_catalog
    from siteline.catalog.models import Scene
    from siteline.catalog.scenes import scene_statistics

    settings, ids = _ingested_home(tmp_path, synth_dir, "c")
    code = (
        "import sys\nfrom siteline.catalog import open_catalog\nfrom siteline.config import load_settings\n"
        "from siteline.tiles.stage import tile_scene\nfrom siteline.pointpass import TilingResources\ns = load_settings()\n"
        "from siteline.catalog.context import StageContext\n"
        "tile_scene(StageContext(open_catalog(s), s), int(sys.argv[1]), resources=TilingResources(workers=1))\n"
    )
    procs = [subprocess.Popen([sys.executable, "-c", code, str(i)], env=_env(settings)) for i in ids]
    assert [p.wait(timeout=300) for p in procs] == [0, 0]
    cat = open_catalog(settings)
    with cat.transaction() as s:
        for i in ids:
            scene = s.get(Scene, i)
            assert scene.status == "tiled"
            tiling = scene_statistics(scene).tiling
            opened = SceneTiles.open(scene.tile_store_uri)
            assert opened.point_count == scene.point_count == tiling.points
            assert len(opened.nodes) == tiling.nodes > 0
    cat.dispose()


def test_stores_with_whole_level_nodes_still_read(tmp_path) -> None:
    """A store of format 1 keeps its node list as JSON in its attributes, one node per tile level
    (no cube), input order inside a node, and calls its int32 counts ``xyz``: every read still works,
    with per-tile culling and whole nodes."""
    import json

    import zarr

    origin = (445_000.0, 5_030_000.0, 80.0)
    geo = _cloud(tmp_path / "c.las", origin, n=20_000)
    spec = TileSpec(node_points=1)  # one level per band (as format 1), cut into cubes
    _, result, tiles = _tile(tmp_path, tmp_path / "c.las", origin, spec=spec)
    for tile in tiles.by_tile:
        os.rename(Path(result.uri, "tiles", tile, "xyz_counts"), Path(result.uri, "tiles", tile, "xyz"))
    docs = []
    for tile, nodes in tiles.by_tile.items():
        for lv in np.unique(nodes.level):
            ns = np.flatnonzero(nodes.level == lv)
            docs.append(
                {"key": f"{tile}/{lv}", "tile": tile, "level": int(lv), "bounds_min": nodes.lo[ns].min(axis=0).tolist(),
                 "bounds_max": nodes.hi[ns].max(axis=0).tolist(), "count": int(nodes.count[ns].sum()),
                 "start": int(nodes.start[ns].min()), "spacing_m": spec.spacing(int(lv)), "cell": None}
            )  # fmt: skip
    root = zarr.open_group(result.uri, mode="a")
    del root["nodes"]
    old_spec = {k: v for k, v in spec.to_dict().items() if k not in ("node_order", "node_points")}
    root.attrs.update({"siteline_tiles": 1, "nodes": docs, "spec": old_spec})
    assert TileSpec.from_dict(old_spec).node_order == "input"
    old = SceneTiles.open(result.uri)
    assert (
        old.spec.node_order == "input"
        and len(old.nodes) == len(docs)
        and "nodes" in json.loads((Path(result.uri) / "zarr.json").read_text())["attributes"]
    )
    cam = Camera.look_at((-40, -50, 30), (5, 5, 0), 320, 240, fx=200.0)
    local = geo - np.asarray(origin)
    planes = cam.scaled(0.5).frustum_planes(1e-3)
    brute = np.flatnonzero(np.all(local @ planes[:, :3].T + planes[:, 3] >= 0, axis=1))
    got = old.points_for_view(cam, 0.5, attributes=("gps_time",), level=None)
    assert set(got.attributes["gps_time"].astype(int)) == set(brute)
    auto = old.points_for_view(cam, 0.125, attributes=("gps_time",))
    assert 0 < len(auto.xyz_m) and set(auto.attributes["gps_time"].astype(int)) <= set(brute)
    chosen = old.levels_for_view(cam, 0.125).selection  # input order: whole nodes only, never a part
    assert all(np.array_equal(take, old.by_tile[t].count[sel]) for t, (sel, take) in chosen.items())


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
    assert tiles.spec.node_order == "reversed-morton"
    tile = max(tiles.by_tile, key=lambda t: tiles.prefix(t))
    nodes = tiles.by_tile[tile]
    k = int(np.argmax(np.diff(nodes.below, axis=1)[np.arange(len(nodes)), nodes.level]))  # largest last level
    head = int(nodes.up_to(int(nodes.level[k]) - 1)[k])  # its coarser levels come first
    part = (int(nodes.count[k]) - head) // 10
    xyz = tiles.read_nodes({tile: (np.array([k]), np.array([head + part]))}, ()).xyz_m[head:]
    span = (xyz.max(axis=0) - xyz.min(axis=0))[:2] / (nodes.hi[k] - nodes.lo[k])[:2]
    assert np.all(span > 0.9), span  # the first tenth of a level spans the node, not a corner of it
    cam = Camera.look_at((0, 0, 40), (0, 0, 0), 150, 125, fx=100.0)  # 0.4 m pixels over 0.1 m data
    every = tiles.points_for_view(cam, 1.0, level=None)
    for size, most in ((1, 6.0), (3, 0.8)):
        settings = RenderParams(scale=1.0, point_size_px=size)
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
    spec = TileSpec(chunk_points=1024, shard_points=8192, node_points=512)
    _, result, tiles = _tile(tmp_path, tmp_path / "c.las", origin, spec=spec)
    tile = max(tiles.by_tile, key=tiles.prefix)
    whole = tiles.read({tile: tiles.prefix(tile)}, ("gps_time",))
    nodes = tiles.by_tile[tile]
    last = len(nodes) - 1  # the last node: at the end of the arrays
    start, count = int(nodes.start[last]), int(nodes.count[last])
    for cache in (256 * 2**20, 4096):
        fresh = SceneTiles(result.uri, tiles.nodes, tiles.spec, cache_bytes=cache)
        got = fresh.read_nodes({tile: (np.array([last]), np.array([count]))}, ("gps_time",))
        want = slice(start, start + count)
        assert np.array_equal(got.attributes["gps_time"], whole.attributes["gps_time"][want])
        assert np.array_equal(got.xyz_m, whole.xyz_m[want])
        first, end = start // 1024, -(-(start + count) // 1024)
        assert got.stats.points_decoded <= 2 * (end - first) * 1024 < tiles.prefix(tile)
        again = fresh.read_nodes({tile: (np.array([last]), np.array([count]))}, ("gps_time",))
        assert (again.stats.points_decoded == 0) == (cache > 4096)


def test_each_level_of_a_node_is_in_node_order_and_compresses(tmp_path) -> None:
    """Default order: inside every (node, level) the stored counts ascend by the reversed Morton key
    (the points of a seeded shuffle, reordered), and its counts take fewer bytes than shuffled."""
    import zarr
    from sitehelpers import node_order_key

    origin = (445_000.0, 5_030_000.0, 80.0)
    rng = np.random.default_rng(8)
    n = 120_000  # 300 points/m2 over 20 x 20 m
    local = np.c_[rng.uniform(0, 20, (n, 2)), rng.normal(0, 0.03, n)]
    write_las(tmp_path / "d.las", local + np.asarray(origin), crs="EPSG:32618")
    stores = {}
    for order in ("reversed-morton", "random"):
        (tmp_path / order).mkdir()
        stores[order] = _tile(tmp_path / order, tmp_path / "d.las", origin, spec=TileSpec(node_order=order))
    (_, result, tiles), (_, shuffled, _) = stores["reversed-morton"], stores["random"]
    assert tiles.spec.node_order == "reversed-morton" and result.points == n
    size = {
        order: sum(f.stat().st_size for f in Path(res.uri, "tiles").glob("*/xyz_counts/**/*") if f.is_file())
        for order, (_, res, _) in stores.items()
    }
    groups = 0
    for tile, nodes in tiles.by_tile.items():
        counts = zarr.open_array(Path(result.uri, "tiles", tile, "xyz_counts"), mode="r")[:]
        other = zarr.open_array(Path(shuffled.uri, "tiles", tile, "xyz_counts"), mode="r")[:]
        key = node_order_key(counts)
        for k in range(len(nodes)):
            ends = int(nodes.start[k]) + nodes.below[k]  # the node's levels, one after another
            for a, b in zip(ends[:-1], ends[1:], strict=True):
                if b - a > 1:
                    groups += 1
                    assert np.all(key[a : b - 1] <= key[a + 1 : b]), (tile, k, a)
                    assert np.array_equal(np.unique(counts[a:b], axis=0), np.unique(other[a:b], axis=0))
    assert groups > 20
    assert size["reversed-morton"] < 0.85 * size["random"], size
