"""Tile array codecs: lossless, and narrower where they can be."""

from __future__ import annotations

import numpy as np
import pytest
import zarr

from siteline.records.tiling import TileSpec
from siteline.tiles.codecs import array_codecs, time_scale


def _stored(tmp_path, name: str, values: np.ndarray) -> tuple[np.ndarray, int, list]:
    arr = zarr.create_array(
        str(tmp_path / name), shape=values.shape, dtype=values.dtype, chunks=(4096, *values.shape[1:]),
        fill_value=0,
        **array_codecs(name, values.dtype, values.ndim, TileSpec(), time_scale(values)),
    )  # fmt: skip
    arr[...] = values
    back = zarr.open_array(str(tmp_path / name), mode="r")
    size = sum(p.stat().st_size for p in (tmp_path / name).rglob("*") if p.is_file())
    return back[...], size, [c.to_dict()["name"] for c in back.metadata.codecs]


def test_microsecond_times_are_stored_as_integers_bit_for_bit(tmp_path) -> None:
    rng = np.random.default_rng(1)
    t = 400_000.0 + np.sort(rng.integers(0, 8_000_000, 20_000)) * 1e-6  # a scanner's microsecond clock
    assert time_scale(t) == 1e6
    shuffled = rng.permutation(t)  # a node's order
    back, size, codecs = _stored(tmp_path, "gps_time", shuffled)
    assert back.dtype == np.float64 and back.tobytes() == shuffled.tobytes()
    assert "numcodecs.fixedscaleoffset" in codecs
    _, plain_size, _ = _stored(tmp_path, "plain", shuffled)  # no filter for other names
    assert size < 0.8 * plain_size


def test_times_round_trip_exactly_whatever_their_resolution(tmp_path) -> None:
    rng = np.random.default_rng(2)
    cases = {
        "whole": np.arange(1000, dtype=np.float64) + 1.2e9,
        "ns": (10**9 + rng.integers(0, 10**9, 1000)) / 1e9,  # what a nanosecond clock decodes to
        "any": rng.uniform(0, 604_800, 1000),  # full float64 mantissas: no scale keeps them
        "nan": np.r_[rng.uniform(0, 1, 999), np.nan],
        "huge": np.array([1e300, -1e300, 0.0]),
    }
    for name, t in cases.items():
        back, _, codecs = _stored(tmp_path / name, "gps_time", t)
        assert back.tobytes() == t.tobytes(), name
        narrowed = "numcodecs.fixedscaleoffset" in codecs
        assert narrowed == (name in ("whole", "ns")), (name, codecs)
    assert time_scale(cases["whole"]) == 1.0


@pytest.mark.parametrize("dtype", ["int32", "uint8", "uint16"])
def test_other_arrays_round_trip(tmp_path, dtype) -> None:
    rng = np.random.default_rng(3)
    values = rng.integers(0, 200, (10_000, 3)).astype(dtype)
    back, _, codecs = _stored(tmp_path, "xyz_counts", values)
    assert back.dtype == values.dtype and np.array_equal(back, values)
    assert codecs[0] == "transpose"  # planar coordinates inside each chunk
