"""The compiled kernels (siteline.kernels) against plain numpy on the same arrays."""

from __future__ import annotations

import numpy as np
import pytest

from siteline.kernels.cut import bounds, runs, tile_codes
from siteline.kernels.radix import radix_order


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


def test_runs_cut_sorted_codes() -> None:
    code = np.array([3, 3, 5, 9, 9, 9])
    z = np.array([4, -2, 7, 1, 0, 3], np.int32)
    codes, first, zmin = runs(code, z)
    assert codes.tolist() == [3, 5, 9] and first.tolist() == [0, 2, 3] and zmin.tolist() == [-2, 7, 0]
