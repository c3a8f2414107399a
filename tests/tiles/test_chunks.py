"""Tile chunks read straight off the disk (siteline.tiles.chunks) give what zarr gives, chunk for
chunk and view for view, and shards written straight are zarr's own bytes; a damaged shard is an
error naming its file; any other layout or store is left to zarr."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import zarr
from zarr.codecs import BloscCodec, BloscShuffle, TransposeCodec
from zarr.storage import LocalStore, MemoryStore

from siteline.camera.pinhole import Camera
from siteline.errors import TileError
from siteline.records.tiling import TileSpec
from siteline.tiles import reader as reader_module
from siteline.tiles.chunks import direct_chunks
from siteline.tiles.codecs import array_codecs, time_scale
from siteline.tiles.layout import ATTRIBUTES
from siteline.tiles.reader import SceneTiles
from tests.tiles.test_tiles import _cloud, _tile

ORIGIN = (445_000.0, 5_030_000.0, 80.0)


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> Path:
    """A scene of 150,000 points in one 50 m tile: each array holds two full inner chunks of
    65,536 points and a cut one."""
    tmp = tmp_path_factory.mktemp("chunks")
    _cloud(tmp / "c.las", (ORIGIN[0] + 25.0, ORIGIN[1] + 25.0, ORIGIN[2]), n=150_000, extent=40.0)
    _, result, _ = _tile(tmp, tmp / "c.las", ORIGIN)
    return Path(result.uri.removeprefix("file://"))


def _arrays(root: Path) -> dict[str, zarr.Array]:
    group = zarr.open_group(LocalStore(root, read_only=True), mode="r")
    return {
        f"{tile}/{name}": arr
        for tile, tg in group["tiles"].groups()
        for name, arr in tg.arrays()
    }  # fmt: skip


def test_every_chunk_is_what_zarr_reads(store) -> None:
    arrays = _arrays(store)
    direct = {k: direct_chunks(a) for k, a in arrays.items()}
    # every array of the store (gps_time's fixed scale/offset included) is read directly
    assert all(d is not None for d in direct.values())
    assert {k.split("/")[1] for k in direct} == set(ATTRIBUTES)
    cut = 0
    for key, d in direct.items():
        if d is None:
            continue
        arr = arrays[key]
        c = int(arr.chunks[0])
        n = -(-arr.shape[0] // c)
        assert n >= 3
        for i in range(n):
            got, want = d.read(i), arr[i * c : (i + 1) * c]
            assert got.dtype == want.dtype and got.flags.c_contiguous and np.array_equal(got, want), (key, i)
            cut += len(got) < c
    assert cut >= 5  # the last chunk of each array, cut at its end


def test_views_read_the_same_points_either_way(store, monkeypatch) -> None:
    cams = [
        Camera.look_at((0.0, 0.0, 40.0), (0.0, 0.0, 0.0), 320, 240, fx=200.0),
        Camera.look_at((-30.0, -10.0, 20.0), (5.0, 0.0, 0.0), 320, 240, fx=300.0),
    ]
    attrs = ("rgb", "class", "gps_time", "intensity")
    fast = SceneTiles.open(f"file://{store}")
    assert fast._direct_of(next(iter(fast.by_tile)), "xyz_counts") is not None
    reads = [fast.points_for_view(cam, 1.0, attributes=attrs) for cam in cams]
    monkeypatch.setattr(reader_module, "direct_chunks", lambda arr: None)
    slow = SceneTiles.open(f"file://{store}")
    for cam, got in zip(cams, reads, strict=True):
        want = slow.points_for_view(cam, 1.0, attributes=attrs)
        assert got.stats.points_read == want.stats.points_read > 10_000
        assert np.array_equal(got.xyz_m, want.xyz_m) and np.array_equal(got.spacing_m, want.spacing_m)
        for a in attrs:
            assert np.array_equal(got.attributes[a], want.attributes[a]), a


def test_a_damaged_shard_names_its_file(store, tmp_path) -> None:
    import shutil

    copy = tmp_path / "scene.zarr"
    shutil.copytree(store, copy)
    arrays = _arrays(copy)
    key = next(k for k in arrays if k.endswith("/rgb"))
    shard = copy / "tiles" / key / "c" / "0" / "0"
    raw = bytearray(shard.read_bytes())
    raw[-10] ^= 0xFF  # the index, under its checksum
    shard.write_bytes(bytes(raw))
    d = direct_chunks(arrays[key])
    assert d is not None
    with pytest.raises(TileError, match=r"c/0/0: the shard's index fails its checksum"):
        d.read(0)
    # cut short: the index is whole (copied from the end) but a chunk's bytes are gone
    raw[-10] ^= 0xFF
    index = bytes(raw[-(16 * d.per_shard + 4) :])
    shard.write_bytes(bytes(raw[:100]) + index)
    d = direct_chunks(_arrays(copy)[key])
    assert d is not None
    with pytest.raises(TileError, match=r"c/0/0: inner chunk 1 is cut short"):
        d.read(1)


def test_chunks_never_written_are_the_fill_value_and_other_layouts_go_to_zarr(tmp_path) -> None:
    blosc = BloscCodec(cname="zstd", clevel=3, shuffle=BloscShuffle.bitshuffle)
    root = zarr.open_group(LocalStore(tmp_path / "g.zarr"), mode="w")
    arr = root.create_array(
        "a", shape=(300, 3), dtype="int32", chunks=(64, 3), shards=(128, 3), fill_value=7,
        filters=[TransposeCodec(order=(1, 0))], compressors=blosc,
    )  # fmt: skip
    arr[:64] = np.arange(192, dtype=np.int32).reshape(64, 3)  # chunk 0 only: 1 empty, shards 1-2 absent
    d = direct_chunks(arr)
    assert d is not None
    for i in range(5):
        assert np.array_equal(d.read(i), arr[i * 64 : (i + 1) * 64]), i
    assert (d.read(3) == 7).all() and len(d.read(4)) == 300 - 256
    plain = root.create_array("b", shape=(100,), dtype="uint8", chunks=(10,), compressors=blosc)
    in_memory = zarr.open_group(MemoryStore(), mode="w").create_array(
        "c", shape=(300, 3), dtype="int32", chunks=(64, 3), shards=(128, 3), compressors=blosc
    )
    assert direct_chunks(plain) is None and direct_chunks(in_memory) is None


def test_shards_written_directly_are_the_bytes_zarr_writes(tmp_path) -> None:
    """Each array of a tile's layout (transposed xyz, a scaled gps_time, plain bytes), 300 rows in
    shards of 128 and chunks of 32: the last shard holds a whole chunk, a cut one and two past the
    end. Written by zarr and by ``write_shard``, the shard files are byte for byte the same, and zarr
    reads the direct ones back."""
    rng = np.random.default_rng(3)
    n = 300
    values = {
        "xyz_counts": rng.integers(-5_000, 90_000, (n, 3)).astype("<i4"),
        "rgb": rng.integers(0, 256, (n, 3)).astype("u1"),
        "intensity": rng.integers(0, 4_000, n).astype("<u2"),
        "gps_time": (400_000_000_000 + 2 * np.arange(n)) / 1e6,
        "class": rng.choice(np.array([1, 2, 6], "u1"), n),
    }
    spec = TileSpec()
    made = {}
    for how in ("zarr", "direct"):
        root = zarr.open_group(LocalStore(tmp_path / f"{how}.zarr"), mode="w")
        for name, v in values.items():
            scale = time_scale(v) if name == "gps_time" else None
            arr = root.create_array(
                name, shape=v.shape, dtype=v.dtype, chunks=(32, *v.shape[1:]), shards=(128, *v.shape[1:]),
                fill_value=0, config={"write_empty_chunks": True},
                **array_codecs(name, v.dtype, v.ndim, spec, scale),
            )  # fmt: skip
            if how == "zarr":
                arr[:] = v
                continue
            d = direct_chunks(arr)
            assert d is not None and (d.filter is not None) == (name == "gps_time")
            for s in range(3):
                d.write_shard(s, v[s * 128 : (s + 1) * 128])
            assert np.array_equal(zarr.open_array(LocalStore(tmp_path / "direct.zarr"), path=name)[:], v)
            assert np.array_equal(np.concatenate([d.read(i) for i in range(10)]), v)
        made[how] = tmp_path / f"{how}.zarr"
    files = sorted(p.relative_to(made["zarr"]) for p in made["zarr"].rglob("*") if p.is_file())
    assert len([f for f in files if "/c/" in str(f)]) == 3 * len(values)
    for f in files:
        assert (made["direct"] / f).read_bytes() == (made["zarr"] / f).read_bytes(), f
    with pytest.raises(TileError, match=r"c/2: shard 2 takes 44 rows, not 40"):
        d.write_shard(2, values["class"][:40])
