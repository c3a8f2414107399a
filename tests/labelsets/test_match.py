"""Matching file points to stored points by key, as multisets."""

from __future__ import annotations

import numpy as np

from siteline.labelsets.match import match_points, point_keys


def _keys(xyz, gps=None, rn=None):
    xyz = np.asarray(xyz, dtype=np.int64).reshape(-1, 3)
    rn = np.ones(len(xyz), np.uint8) if rn is None else np.asarray(rn, np.uint8)
    return point_keys(xyz, None if gps is None else np.asarray(gps, float), rn)


def test_reordered_points_match_one_to_one() -> None:
    rng = np.random.default_rng(0)
    xyz = rng.integers(-(2**40), 2**40, size=(1000, 3))
    gps = rng.random(1000) * 1e6
    stored = _keys(xyz, gps)
    perm = rng.permutation(1000)
    m = match_points(stored, stored[perm])
    assert len(m.stored) == 1000 and not m.duplicated.any() and not m.unmatched.any()
    assert np.array_equal(m.stored, perm[m.incoming])


def test_gps_time_and_return_number_separate_points_at_one_position() -> None:
    stored = _keys([[1, 2, 3]] * 3, gps=[5.0, 5.0, 6.0], rn=[1, 2, 1])
    incoming = _keys([[1, 2, 3]] * 3, gps=[6.0, 5.0, 5.0], rn=[1, 2, 1])
    m = match_points(stored, incoming)
    pairs = dict(zip(m.incoming.tolist(), m.stored.tolist(), strict=True))
    assert pairs == {0: 2, 1: 1, 2: 0}


def test_duplicates_and_strangers_are_told_apart() -> None:
    stored = _keys([[0, 0, 0], [1, 1, 1], [1, 1, 1]])
    incoming = _keys([[1, 1, 1], [1, 1, 1], [1, 1, 1], [0, 0, 0], [9, 9, 9]])
    m = match_points(stored, incoming)
    assert len(m.stored) == 3 and sorted(m.stored.tolist()) == [0, 1, 2]
    assert m.duplicated.tolist() == [False, False, True, False, False]
    assert m.unmatched.tolist() == [False, False, False, False, True]


def test_one_quantum_apart_does_not_match_and_empty_sides_work() -> None:
    m = match_points(_keys([[0, 0, 0]]), _keys([[0, 0, 1]]))
    assert len(m.stored) == 0 and m.unmatched.all()
    m = match_points(_keys(np.zeros((0, 3))), _keys([[0, 0, 0]]))
    assert m.unmatched.all()
    m = match_points(_keys([[0, 0, 0]]), _keys(np.zeros((0, 3))))
    assert len(m.stored) == 0 and len(m.unmatched) == 0
