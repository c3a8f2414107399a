"""Co-registration direction by direction: what the stable surfaces leave free (x, y and yaw over flat
ground) is fixed by the structure of any kept class, and what nothing fixes is said, never claimed."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from siteline.records.registration import Alignment
from siteline.register.icp import STRUCTURE, SURFACES, register_samples
from siteline.register.scene import AlignmentPolicy, check_alignment

SHIFT = np.array([1.2, -0.8, 0.3])
TURN = Rotation.from_euler("z", 0.2, degrees=True).as_matrix()


def _forest(seed: int, density: float = 1.5, size: float = 200.0) -> tuple[np.ndarray, np.ndarray]:
    """Flat ground and tree crowns sampled at ``density`` points/m2 (a fresh sampling per seed of the
    same trees, as two flights see them)."""
    rng = np.random.default_rng(seed)
    n = int(density * size * size)
    ground = np.c_[rng.uniform(-size / 2, size / 2, (n, 2)), rng.normal(0, 0.03, n)]
    trees = np.random.default_rng(7)
    centres = trees.uniform(-size / 2 + 5, size / 2 - 5, (120, 2))
    radii, heights = trees.uniform(2, 5, 120), trees.uniform(8, 20, 120)
    crowns = []
    for c, r, h in zip(centres, radii, heights, strict=True):
        d = rng.normal(size=(int(density * 2 * np.pi * r * r), 3))
        d[:, 2] = np.abs(d[:, 2])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        crowns.append(np.c_[c + d[:, :2] * r, h + d[:, 2] * r * 0.6])
    return ground, np.concatenate(crowns)


def _moved(p: np.ndarray) -> np.ndarray:
    return p @ TURN.T + SHIFT


def _error_m(correction: list[list[float]], probes: np.ndarray) -> float:
    M = np.asarray(correction)
    back = _moved(probes) @ M[:3, :3].T + M[:3, 3]
    return float(np.linalg.norm(back - probes, axis=1).max())


PROBES = np.array([[60.0, 60.0, 0.0], [-80.0, 30.0, 0.0], [0.0, -90.0, 10.0]])


def test_trees_fix_what_flat_ground_leaves_free() -> None:
    g1, t1 = _forest(1)
    g2, t2 = _forest(2)
    res = register_samples(_moved(g2), g1, _moved(t2), t1)
    assert _error_m(res.correction, PROBES) < 0.1  # found within 0.1 m everywhere on the site
    assert {res.axes[a] for a in ("z", "roll", "pitch")} == {SURFACES}
    assert {res.axes[a] for a in ("x", "y", "yaw")} == {STRUCTURE}
    assert not res.free and res.residual_xy_m is not None and res.residual_xy_m > 0.05


def test_flat_ground_alone_reports_the_free_directions() -> None:
    g1, _ = _forest(1)
    g2, _ = _forest(2)
    res = register_samples(_moved(g2), g1)
    assert sorted(res.free) == ["x", "y", "yaw"]
    # the free directions are left at zero: only z was moved (0.3 m), nothing claimed across
    assert res.translation_m == pytest.approx(0.3, abs=0.02)
    text = Alignment(
        1, res.translation_m, res.rotation_deg, True, res.residual_m, res.residual_xy_m, dict(res.axes)
    ).summary()
    assert "yaw, x, y NOT CHECKED" in text and "m across" not in text


def _one_tree(seed: int, n: int = 300) -> np.ndarray:
    """A tree at (-40, -10): a 3 m crown of leaves sampled afresh per seed (other leaves each flight)
    on a trunk."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    crown = np.c_[np.array([-40.0, -10.0]) + d[:, :2] * 3.0, 6.5 + d[:, 2] * 1.5]
    a = rng.uniform(0, 2 * np.pi, n // 4)
    trunk = np.c_[-40 + 0.25 * np.cos(a), -10 + 0.25 * np.sin(a), rng.uniform(0, 5, n // 4)]
    return np.r_[crown, trunk]


def test_one_tree_fixes_the_shift_but_never_claims_the_yaw() -> None:
    """A tree alone turns the scene about itself as freely as it shifts it: its leaves turned a flown
    box scene by 7.8 degrees (5 degrees here before the rule), 5.6 m at the site's edge."""
    g1, _ = _forest(1, size=100.0)
    g2, _ = _forest(2, size=100.0)
    res = register_samples(_moved(g2), g1, _moved(_one_tree(5)), _one_tree(6))
    assert res.axes["yaw"] is None and {res.axes["x"], res.axes["y"]} == {STRUCTURE}
    assert res.rotation_deg < 0.05  # nothing turned about the tree
    assert np.abs(np.asarray(res.correction)[:2, 3] + SHIFT[:2]).max() < 0.3  # the shift found at the tree


def test_a_cloud_without_ground_or_building_registers_on_every_class() -> None:
    g1, t1 = _forest(1)
    g2, t2 = _forest(2)
    res = register_samples(np.zeros((0, 3)), np.zeros((0, 3)), _moved(np.r_[g2, t2]), np.r_[g1, t1])
    assert res.surfaces.startswith("every kept class")
    assert _error_m(res.correction, PROBES) < 0.1 and not res.free


def test_the_ingest_check_splits_the_sample_by_kind_and_applies_the_correction() -> None:
    g1, t1 = _forest(1)
    g2, t2 = _forest(2)

    def sample(g: np.ndarray, t: np.ndarray) -> np.ndarray:
        return np.r_[np.c_[g, np.ones(len(g))], np.c_[t, np.full(len(t), 2.0)]]

    record = check_alignment(sample(_moved(g2), _moved(t2)), sample(g1, t1), 1, "m2", AlignmentPolicy())
    assert record.applied and not record.free
    assert _error_m(record.correction, PROBES) < 0.1
    # an older scene's sample of stable surfaces only (N, 3): its free directions are named
    old = check_alignment(sample(_moved(g2), _moved(t2)), g1, 1, "m2", AlignmentPolicy())
    assert sorted(old.free) == ["x", "y", "yaw"]
