"""The surface rule against py4dgeo's M3C2 (the field's library) on the same two synthetic epochs:
per-point precision and recall of "changed" against the generator's truth flags, and seconds, one
direction (t1 against t2), in one run.

    python bench/m3c2.py [--density 10] [--out bench-m3c2]     (needs `pip install py4dgeo`)
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import laspy
import numpy as np

from siteline.labels.change import CHANGED, Matching, change_flags, median_spacing
from siteline.labels.regions import small_regions
from siteline.records.params.labels import SurfaceTest
from siteline.site.taxonomy import default_taxonomy
from siteline.synth import LAS_RELPATH, SynthParams, write_site


def _epoch(site: Path, doc: dict, i: int, key: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    e = doc["epochs"][i]
    las = laspy.read(site / e["mission_dir"] / LAS_RELPATH)
    xyz = np.c_[las.x, las.y, las.z] - np.asarray(doc["origin"])
    lut, _ = default_taxonomy().code_lut("las")
    return (
        xyz,
        lut[np.asarray(las.classification)].astype(np.uint8),
        np.load(site / "truth" / e["name"] / f"{key}.npy"),
    )


def _score(name: str, pred: np.ndarray, truth: np.ndarray, seconds: float) -> dict:
    tp, fp, fn = int((pred & truth).sum()), int((pred & ~truth).sum()), int((~pred & truth).sum())
    row = {"method": name, "precision": tp / max(tp + fp, 1), "recall": tp / max(tp + fn, 1), "seconds": seconds,
           "false_changed": fp}  # fmt: skip
    print(f"{name:>28}: P {row['precision']:.3f} R {row['recall']:.3f} false {fp:,} in {seconds:.1f} s")
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--density", type=float, default=10.0)
    ap.add_argument("--out", type=Path, default=Path("bench-m3c2"))
    args = ap.parse_args()
    import py4dgeo

    site = args.out / f"site-{args.density:g}"
    if not (site / "truth" / "site.json").exists():
        write_site(
            site,
            SynthParams(
                epochs=2,
                density_pts_m2=args.density,
                snow_epochs=(),
                projection_error_epochs=(),
                photos=False,
                colmap=False,
            ),
        )
    doc = json.loads((site / "truth" / "site.json").read_text())
    a, ac, truth = _epoch(site, doc, 0, "changed_until_next")
    b, bc, _ = _epoch(site, doc, 1, "changed_since_previous")
    ign = default_taxonomy().ignored_lut()
    r = 2.5 * max(median_spacing(a), median_spacing(b))
    print(f"{len(a):,} / {len(b):,} points, r = {r:.3f} m")
    rows = []
    t = time.perf_counter()
    near = change_flags(a, ac, b, bc, r, ign) == CHANGED
    rows.append(_score("nearest", near, truth, time.perf_counter() - t))
    t = time.perf_counter()
    surf = change_flags(a, ac, b, bc, r, ign, Matching(surface=SurfaceTest(2 * r))) == CHANGED
    surf[np.flatnonzero(surf)[small_regions(a[surf], 2 * r, 8)]] = False
    rows.append(_score("surface + regions of 8", surf, truth, time.perf_counter() - t))
    for cyl in (r, 2 * r):
        t = time.perf_counter()
        m3c2 = py4dgeo.M3C2(
            epochs=(py4dgeo.Epoch(a), py4dgeo.Epoch(b)), corepoints=a, cyl_radius=cyl, normal_radii=(2 * r,),
            max_distance=50.0, registration_error=0.0,
        )  # fmt: skip
        d, unc = m3c2.run()
        lod = unc["lodetection"]
        seconds = time.perf_counter() - t
        moved = np.isfinite(d) & (np.abs(d) > np.maximum(lod, 0.05))
        # no correspondence along the normal (NaN): nothing of t2 there (changed), or unknown (not)
        rows.append(_score(f"M3C2 cyl {cyl:.2f} m, NaN changed", moved | ~np.isfinite(d), truth, seconds))
        rows.append(_score(f"M3C2 cyl {cyl:.2f} m, NaN unchanged", moved, truth, seconds))
    (args.out / "m3c2.json").write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
