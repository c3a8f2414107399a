"""Ground from geometry and the terrain model: the progressive morphological filter
(siteline.views.groundfilter) against the cloth simulation filter (the ``cloth-simulation-filter``
package, when installed: it is not a dependency) on the two real airborne clouds of tests/data/real,
and what the ground model costs on a 10M-point scene.

Truth for the real clouds: a point is ground when it lies within 0.3 m of the surface interpolated
(linearly) through the file's own ground class (ASPRS 2), inside that class's hull. Their ground
class is incomplete (autzen leaves two thirds of its ground-level points unclassified), so the class
itself is no truth; the surface it spans is.

    python bench/ground.py [--points 10000000]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import laspy
import numpy as np
from scipy.interpolate import griddata

from siteline.views.ground import model_ground
from siteline.views.groundfilter import MorphologyParams, morphological_ground

REAL = Path(__file__).resolve().parents[1] / "tests" / "data" / "real"


def _csf(xyz: np.ndarray, resolution: float) -> np.ndarray | None:
    try:
        import CSF  # noqa: N811  (the package's own name)
    except ImportError:
        return None
    c = CSF.CSF()
    c.params.bSloopSmooth = True
    c.params.cloth_resolution = resolution
    c.params.rigidness = 2
    c.params.class_threshold = 0.5
    c.setPointCloud(np.ascontiguousarray(xyz, dtype=np.float64))
    ground, rest = CSF.VecInt(), CSF.VecInt()
    c.do_filtering(ground, rest, False)
    out = np.zeros(len(xyz), bool)
    out[np.array(ground, dtype=np.int64)] = True
    return out


def real_clouds() -> None:
    for name, feet in (("autzen_trim.laz", True), ("topography.laz", False)):
        las = laspy.read(REAL / name)
        xyz = np.c_[las.x, las.y, las.z] * (0.3048 if feet else 1.0)
        xyz -= xyz.mean(axis=0)
        cls = np.asarray(las.classification)
        zg = griddata(xyz[cls == 2, :2], xyz[cls == 2, 2], xyz[:, :2], method="linear")
        hull = np.isfinite(zg)
        truth = np.abs(xyz[:, 2] - np.where(hull, zg, 0.0)) < 0.3
        print(
            f"{name}: {len(xyz):,} points, ground by the truth {truth[hull].mean():.0%} (class 2: {(cls == 2).mean():.0%})"
        )
        runs = [
            (
                f"morphology, {c:g} m cells",
                lambda c=c, xyz=xyz: morphological_ground(xyz, MorphologyParams(cell_m=c)),
            )
            for c in (1.0, 2.0)
        ]
        runs += [(f"CSF, cloth {r:g} m", lambda r=r, xyz=xyz: _csf(xyz, r)) for r in (0.5, 1.0, 2.0)]
        for label, run in runs:
            t = time.perf_counter()
            found = run()
            seconds = time.perf_counter() - t
            if found is None:
                print(f"  {label}: not installed")
                continue
            f, g = found[hull], truth[hull]
            tp = int((f & g).sum())
            print(
                f"  {label}: precision {tp / max(f.sum(), 1):.3f} recall {tp / g.sum():.3f} in {seconds:.2f} s"
            )


def scene_cost(points: int) -> None:
    """A hillside (flat, then 20 % up, a 12 m pit) with buildings, at the density giving ``points``
    over 200 x 200 m: the ground model from its class, and from geometry (no class)."""
    rng = np.random.default_rng(0)
    n = points
    xy = rng.uniform(-100, 100, (n, 2))
    z = 0.2 * np.maximum(xy[:, 0], 0) - np.clip(27.0 - np.hypot(xy[:, 0] - 40, xy[:, 1] + 30), 0, 12)
    roofs = rng.random(n) < 0.15
    z = z + np.where(roofs, rng.uniform(3, 15, n), rng.normal(0, 0.03, n))
    xyz = np.c_[xy, z]
    print(f"a {n:,}-point hillside ({n / 40_000:.0f} points/m2):")
    for label, cls in (("ground class", ~roofs), ("no ground class", np.zeros(n, bool))):
        t = time.perf_counter()
        choice = model_ground(xyz, cls)
        print(
            f"  {label}: {choice.kind} from {choice.source} ({choice.share:.0%} ground, departs from a plane by "
            f"{choice.residual_m:.1f} m) in {time.perf_counter() - t:.1f} s"
        )
    # what a pair reads for it: the scene at 0.5 m (siteline.pairs.execute.scene_ground)
    keep = rng.random(n) < min(1.0, 40_000 * 4 / n)
    t = time.perf_counter()
    choice = model_ground(xyz[keep], np.zeros(int(keep.sum()), bool))
    print(
        f"  as a pair reads it (about 4 points/m2, {int(keep.sum()):,} points): {choice.kind} in {time.perf_counter() - t:.2f} s"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=10_000_000)
    args = ap.parse_args()
    real_clouds()
    scene_cost(args.points)


if __name__ == "__main__":
    main()
