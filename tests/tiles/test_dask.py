"""Tiling on a Dask cluster: the cluster's workers write the tiles straight into the object store
they share (the S3 test server), and the store is the one this machine writes."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pyproj
import pytest

from siteline.pointpass import TilingResources, write_las
from siteline.records.tiling import TileSpec
from siteline.site.spec import make_site_spec
from siteline.stores import open_store
from siteline.tiles.reader import SceneTiles
from siteline.tiles.writer import TileInput, write_tiles

ORIGIN = (445_000.0, 5_030_000.0, 80.0)


@pytest.fixture(scope="module")
def client(s3_endpoint) -> Iterator:
    """A local Dask cluster of two worker processes, shared by this module's tests (started after the S3
    server, so its workers inherit its configuration)."""
    from distributed import Client, LocalCluster

    with (
        LocalCluster(n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None) as cluster,
        Client(cluster) as c,
    ):
        yield c


@pytest.mark.parametrize("where", ["s3", "local"])
def test_a_dask_cluster_writes_the_tiles_into_the_shared_store(tmp_path, request, client, where) -> None:
    from distributed import get_task_stream

    from siteline.stores.remote import file_system

    rng = np.random.default_rng(5)
    n = 60_000
    local = np.c_[rng.uniform(-45, 45, (n, 2)), rng.normal(0, 0.3, n)]
    write_las(tmp_path / "c.las", local + np.asarray(ORIGIN), crs="EPSG:32618",
              classification=np.full(n, 2, np.uint8), gps_time=np.arange(n) * 1e-5)  # fmt: skip
    site = make_site_spec("t", "EPSG:32618", ORIGIN)
    crs = pyproj.CRS("EPSG:32618")
    spec = TileSpec(node_points=1024)
    here = write_tiles(
        TileInput(tmp_path / "c.las", site, crs), tmp_path / "here.zarr", spec, TilingResources(workers=1)
    )
    url = request.getfixturevalue("s3_store") if where == "s3" else str(tmp_path / "stores")
    store = open_store(url, tmp_path / "staging")
    store.ensure()
    uri = store.uri("tiles", "scene-1.zarr")
    with get_task_stream(client) as stream, store.publish_shared(uri) as target:
        there = write_tiles(TileInput(tmp_path / "c.las", site, crs), target, spec, TilingResources(batch_points=5_000, executor=client.get_executor(), scratch=store.staging))  # fmt: skip
    assert there.checksum == here.checksum and there.points == n and there.tiles == here.tiles == 4
    wrote = [t for t in stream.data if "write_tile" in str(t["key"])]
    assert len(wrote) == there.tiles and len({t["worker"] for t in wrote}) == 2  # both workers wrote
    assert store.is_complete(uri)
    a, b = SceneTiles.open(here.uri), SceneTiles.open(uri)
    for tile in a.by_tile:
        assert np.array_equal(a.read_tile(tile, ("gps_time",)).xyz_m, b.read_tile(tile, ("gps_time",)).xyz_m)
    fs, tiles = file_system(store.uri("tiles"))
    fs.invalidate_cache()
    assert [p.rstrip("/").rsplit("/", 1)[-1] for p in fs.ls(tiles)] == ["scene-1.zarr"]  # runs removed
    assert not list((tmp_path / "staging").glob(".*spill*"))
