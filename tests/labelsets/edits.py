"""Exports and edits of a scene's labels, as a person correcting them in a LAS editor would."""

from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np

from siteline.catalog.labelsets import label_sets
from siteline.labelsets.export import export_label_set


def export(cat, scene_id: int, out: Path, version: int | None = None, bounds=None) -> laspy.LasData:  # noqa: ANN001
    """``scene export`` through the library (the CLI test runs the executable)."""
    export_label_set(cat, scene_id, out, version, bounds)
    return laspy.read(out)


def versions(cat, scene_id: int) -> list[int]:  # noqa: ANN001
    with cat.transaction() as s:
        return [r.version for r in label_sets(s, scene_id)]


def shuffled(las: laspy.LasData, seed: int = 0) -> tuple[laspy.LasData, np.ndarray]:
    """The file's points in another order (as an editor may write them), and the permutation."""
    perm = np.random.default_rng(seed).permutation(len(las.points))
    las.points = las.points[perm]
    return las, perm


def centre_box(las: laspy.LasData, half_m: float) -> np.ndarray:
    """Points within ``half_m`` (x and y) of the cloud's median position."""
    x, y = np.asarray(las.x), np.asarray(las.y)
    return (np.abs(x - np.median(x)) < half_m) & (np.abs(y - np.median(y)) < half_m)
