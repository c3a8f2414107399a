"""The view read's compiled pass (siteline.tiles.kernels) against the numpy it replaced."""

from __future__ import annotations

import numpy as np

from siteline.pointpass import dequantise
from siteline.tiles.kernels import place_points


def test_place_points_keeps_what_numpy_dequantise_and_the_frustum_test_keep() -> None:
    rng = np.random.default_rng(3)
    counts = rng.integers(-(2**30), 2**30, (5000, 3)).astype(np.int32)
    local = np.sort(rng.choice(5000, 1200, replace=False)).astype(np.int64)
    crossing = rng.random(1200) < 0.5
    origin = np.array([4_500_000.25, -1_250_000.5, 812.125])  # far from 0: float64 all the way
    quantum = 1e-4
    normals = rng.normal(size=(6, 3))
    planes = np.c_[normals, -(dequantise(counts[local[:6]], origin, quantum) * normals).sum(axis=1)]
    out_xyz, out_rows = np.full((1300, 3), np.nan), np.full(1300, -1, np.int64)
    n = place_points(counts, local, crossing, np.r_[origin, quantum], planes, out_xyz, out_rows, 7)
    xyz = dequantise(counts[local], origin, quantum)
    inside = np.all(xyz @ planes[:, :3].T + planes[:, 3] >= 0, axis=1)
    kept = ~crossing | inside
    assert 0 < kept.sum() < len(kept) and (~inside & ~crossing).any()  # both answers, and kept uncrossed
    assert n == 7 + kept.sum()
    assert np.array_equal(out_xyz[7:n], xyz[kept])  # bit for bit
    assert np.array_equal(out_rows[7:n], np.flatnonzero(kept))
    assert np.isnan(out_xyz[:7]).all() and np.isnan(out_xyz[n:]).all()  # nothing written elsewhere
