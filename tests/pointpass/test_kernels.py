"""The compiled kernels (siteline.pointpass.kernels) against plain numpy on the same arrays."""

from __future__ import annotations

import numpy as np
import pytest
from sitehelpers import node_order_key

from siteline.pointpass.kernels.cut import bounds, tile_codes
from siteline.pointpass.kernels.radix import radix_order, run_starts


@pytest.mark.parametrize("bits", [0, 4, 16, 17, 33, 62])
def test_radix_order_is_a_stable_argsort(bits: int) -> None:
    rng = np.random.default_rng(bits)
    key = rng.integers(-(1 << bits), (1 << bits) + 1, 5_000)
    assert np.array_equal(radix_order(key), np.argsort(key, kind="stable"))


def test_radix_order_of_extremes_and_nothing() -> None:
    key = np.array([np.iinfo(np.int64).max, np.iinfo(np.int64).min, 0, -1, np.iinfo(np.int64).min])
    assert np.array_equal(radix_order(key), np.argsort(key, kind="stable"))
    assert radix_order(np.zeros(0, np.int64)).shape == (0,)


def test_bounds_count_and_skip_non_finite_points() -> None:
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(1000, 3)) * 1e6
    pts[7, 1], pts[9, 2] = np.nan, -np.inf
    lo, hi, bad = bounds(pts)
    good = np.delete(pts, [7, 9], axis=0)
    assert bad == 2
    assert np.array_equal(lo, good.min(axis=0)) and np.array_equal(hi, good.max(axis=0))


def test_tile_codes_match_numpy() -> None:
    rng = np.random.default_rng(2)
    tile_m, quantum_m, edge, side = 50.0, 0.001, 4096, 13
    local = np.c_[rng.uniform(-120, 80, (20_000, 2)), rng.normal(0, 30, 20_000)]
    local[:5, :2] = [[0.0, 0.0], [49.9999999, 0.0], [-1e-9, 50.0], [50.0, -50.0], [-0.0004, 0.0]]
    counts, code = np.empty((len(local), 3), np.int32), np.empty(len(local), np.int64)
    lo_i, lo_j, span_j, far = tile_codes(local, tile_m, quantum_m, edge, side, counts, code)
    ij = np.floor(local[:, :2] * (1.0 / tile_m)).astype(np.int64)
    q = local.copy()
    q[:, :2] -= ij * tile_m
    expect = np.rint(q * (1.0 / quantum_m)).astype(np.int32)
    assert np.array_equal(counts, expect)
    assert (lo_i, lo_j, span_j) == (ij[:, 0].min(), ij[:, 1].min(), ij[:, 1].max() - ij[:, 1].min() + 1)
    assert far == np.abs(expect).max()
    b = np.clip(expect[:, :2] // edge, 0, side - 1)
    tile = (ij[:, 0] - lo_i) * span_j + ij[:, 1] - lo_j
    assert np.array_equal(code, tile * side * side + b[:, 1] * side + b[:, 0])


def test_tile_codes_report_an_overflow() -> None:
    local = np.array([[1.0, 1.0, 3.0e6]])  # 3e9 quanta of a millimetre
    _, _, _, far = tile_codes(local, 50.0, 0.001, 4096, 13, np.empty((1, 3), np.int32), np.empty(1, np.int64))
    assert far >= 2**31 - 1


def test_run_starts_cut_sorted_codes() -> None:
    code = np.array([3, 3, 5, 9, 9, 9])
    assert run_starts(code).tolist() == [0, 2, 3]
    assert run_starts(np.zeros(0, np.int64)).shape == (0,)


def test_cube_rows_count_points_per_level_and_cube() -> None:
    from siteline.pointpass.kernels.nodes import cube_rows
    from siteline.pointpass.schema import LEVEL_SHIFT, Z_OFFSET

    rng = np.random.default_rng(3)
    counts = np.c_[rng.integers(-5, 50_000, (20_000, 2)), rng.integers(-3_000, 9_000, 20_000)].astype(
        np.int32
    )
    levels = rng.integers(0, 8, 20_000).astype(np.uint8)
    edge, depth = 781, 6
    cubes = np.floor_divide(counts, edge).astype(np.int64)
    cubes[:, :2] = np.clip(cubes[:, :2], 0, (1 << depth) - 1)
    key = (
        levels.astype(np.int64) << LEVEL_SHIFT
        | (cubes[:, 2] + Z_OFFSET) << 2 * depth
        | cubes[:, 1] << depth
        | cubes[:, 0]
    )
    want_key, want_count = np.unique(key, return_counts=True)
    rows = cube_rows(counts, levels, edge, depth)
    assert np.array_equal(rows[:, 0], want_key) and np.array_equal(rows[:, 1], want_count)
    far = counts.copy()
    far[0, 2] = 2**31 - 1
    assert cube_rows(far, levels, 1, depth).shape == (0, 2)  # z beyond the key's reach: refused


@pytest.mark.parametrize("shuffle", [True, False])
def test_place_points_fill_a_group_alike_in_any_batches(shuffle: bool) -> None:
    """One group of 1,000 slots starting at 7: placed in one batch or in uneven batches, its points
    take the same slots, each once (the seeded permutation, or in order)."""
    from siteline.pointpass.kernels.nodes import group_points, slot_points

    n = 1_000
    counts, levels = np.zeros((n, 3), np.int32), np.zeros(n, np.uint8)
    grid, key, start, size = (781, 6, 0, 1), np.array([0]), np.array([7]), np.array([n])
    band_of_level, depth_of_band = np.zeros(8, np.int64), np.zeros(1, np.int64)

    def place_points(a: int, b: int, seen: np.ndarray) -> np.ndarray:
        group = group_points(counts[a:b], levels[a:b], grid, band_of_level, depth_of_band, key)
        return slot_points(group, start, size, seen, 42, shuffle)

    def place(cuts: list[int]) -> np.ndarray:
        seen = np.zeros(1, np.int64)
        out = [place_points(a, b, seen) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
        assert seen[0] == n
        return np.concatenate(out)

    whole = place([0, n])
    assert np.array_equal(place([0, 1, 300, 301, 999, n]), whole)
    assert np.array_equal(np.sort(whole), np.arange(7, 7 + n))
    assert (whole[:-1] < whole[1:]).all() != shuffle
    seen = np.array([n - 1])  # one slot left for two points: no group to place them in
    assert (place_points(0, 2, seen) == -1).all()


def test_node_order_sorts_each_group_by_its_reversed_morton_code_stably() -> None:
    """Groups small (insertion) and large (counting), with negative counts and duplicates: each
    sorted by the key, ties in input order, never a point across groups."""
    from siteline.pointpass.kernels import order_key
    from siteline.pointpass.kernels.nodes import order_in_groups

    rng = np.random.default_rng(5)
    counts = rng.integers(-(2**20), 2**20, (20_000, 3)).astype(np.int32)
    counts[100:400] = counts[100:103].repeat(100, axis=0)  # duplicates in a large group
    counts[5:9] = counts[5]  # and in a small one
    sizes = np.array([0, 1, 2, 40, 64, 65, 3_000, 12_000])
    sizes = np.r_[sizes, len(counts) - sizes.sum()]
    bounds = np.r_[0, np.cumsum(sizes)]
    key = node_order_key(counts)
    assert [order_key(*map(int, c)) for c in counts[:50]] == key[:50].tolist()
    assert order_key(1, 0, 0) == 1 << 11 and order_key(0, 0, 8) == 1  # bit 0 of x leads
    want = np.concatenate(
        [a + np.argsort(key[a:b], kind="stable") for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    )
    assert np.array_equal(order_in_groups(counts, bounds), want)
    assert order_in_groups(counts[:0], np.zeros(1, np.int64)).shape == (0,)


def test_las_coordinates_and_colour_as_laspy_computes_them() -> None:
    """scaled_xyz is laspy's count * scale + offset bit for bit (no fused multiply-add), at
    georeferenced magnitudes; colour_u8 keeps the high byte of 16-bit colour or the 0-255 value."""
    from siteline.pointpass.kernels.cut import colour_u8, scaled_xyz

    rng = np.random.default_rng(4)
    x, y, z = (rng.integers(-(2**31), 2**31 - 1, 20_000).astype(np.int32) for _ in range(3))
    scale, offset = np.array([0.000123, 0.01, 0.001]), np.array([5_030_123.456789, 445_001.1, -12.3])
    want = np.stack([x * scale[0] + offset[0], y * scale[1] + offset[1], z * scale[2] + offset[2]], axis=1)
    assert scaled_xyz(x, y, z, scale, offset).tobytes() == want.tobytes()
    rgb = rng.integers(0, 2**16, (3, 1000)).astype(np.uint16)
    assert np.array_equal(colour_u8(*rgb, 8), (rgb.T >> 8).astype(np.uint8))
    small = rgb % 256
    assert np.array_equal(colour_u8(*small, 0), small.T.astype(np.uint8))


def _records(n: int, seed: int) -> np.ndarray:
    from siteline.pointpass.schema import RECORD

    rng = np.random.default_rng(seed)
    rec = np.zeros(n, RECORD)
    rec["xyz_counts"] = rng.integers(-(2**31), 2**31 - 1, (n, 3))
    rec["rgb"] = rng.integers(0, 256, (n, 3))
    rec["intensity"] = rng.integers(0, 2**16, n)
    rec["class"] = rng.integers(0, 256, n)
    rec["gps_time"] = rng.normal(4e5, 1e3, n)
    rec["return_number"] = rng.integers(0, 8, n)
    return rec


def test_records_split_into_fields_and_scatter_back_as_numpy_does() -> None:
    """split_records gathers each field of records rec[order] (numpy's fancy index of each field);
    scatter_records puts fields back into records at given places; inverse inverts a permutation."""
    from siteline.pointpass.kernels.radix import inverse
    from siteline.pointpass.kernels.rows import scatter_records, split_records

    rec = _records(5_000, 0)
    order = np.random.default_rng(1).permutation(len(rec))[:3_000]
    fields = [
        np.empty((len(order), *rec.dtype[name].shape), rec.dtype[name].base) for name in rec.dtype.names
    ]
    split_records(rec, order, *fields)
    for name, got in zip(rec.dtype.names, fields, strict=True):
        assert np.array_equal(got, rec[name][order]), name
    full = np.random.default_rng(2).permutation(len(rec))
    assert np.array_equal(inverse(full), np.argsort(full))
    out = np.zeros(len(rec), rec.dtype)  # point i of the fields (record full[i]) back to full[i]
    scatter_records(full, *(np.ascontiguousarray(rec[name][full]) for name in rec.dtype.names), out)
    assert out.tobytes() == rec.tobytes()
