"""Scoring anyone's predictions against a release's ignore-aware truth (one confusion matrix)."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from siteline.errors import ReleaseError
from siteline.metrics import confusion, per_image_scores, scores
from siteline.release.layout import ignore_aware_folder
from siteline.release.manifest import MANIFEST, METRIC_DEFINITION, read_manifest


def read_prediction(path: Path) -> np.ndarray:
    """A prediction PNG as (H, W) int64 0/1: 0/255 (LEVIR-CD) and 0/1 encodings are accepted."""
    try:
        with Image.open(path) as im:
            arr = np.asarray(im.convert("L") if im.mode not in ("L", "P", "1") else im)
    except OSError as exc:
        raise ReleaseError(f"prediction {path} is not a readable image: {exc}") from exc
    values = set(np.unique(arr).tolist())
    if values <= {0, 255}:
        return (arr == 255).astype(np.int64)
    if values <= {0, 1}:
        return arr.astype(np.int64)
    raise ReleaseError(
        f"prediction {path} holds values {sorted(values)[:6]}: write 0 (unchanged) and 255 (or 1) for changed."
    )


def score_predictions(root: Path, split: str, pred_dir: Path) -> dict[str, Any]:
    """Scores of the PNGs ``pred_dir/<id>.png`` against ``split`` of the release at ``root``.

    Every item of the split needs a prediction of the stored (padded) size; the truth's 255 pixels
    (ignore, padding) are excluded. Raises :class:`ReleaseError` naming missing or mis-sized files.
    """
    root, pred_dir = Path(root), Path(pred_dir)
    doc = read_manifest(root)
    if split not in ("train", "val", "test"):
        raise ReleaseError(f"split {split!r} is not one of train, val, test.")
    if not pred_dir.is_dir():
        raise ReleaseError(f"prediction folder {pred_dir} does not exist.")
    items = sorted((it for it in doc["items"] if it["split"] == split), key=lambda it: it["id"])
    if not items:
        raise ReleaseError(f"release {doc['name']} {doc['version']} has no {split} images.")
    missing = [it["id"] for it in items if not (pred_dir / f"{it['id']}.png").is_file()]
    if missing:
        raise ReleaseError(
            f"prediction folder {pred_dir} lacks {len(missing)} of {len(items)} {split} images, e.g. "
            f"{', '.join(m + '.png' for m in missing[:3])}."
        )
    folder = ignore_aware_folder(doc)
    per_image = []
    for it in items:
        truth = np.asarray(Image.open(root / split / folder / f"{it['id']}.png"), dtype=np.int64)
        pred_path = pred_dir / f"{it['id']}.png"
        pred = read_prediction(pred_path)
        if pred.shape != truth.shape:
            raise ReleaseError(
                f"prediction {pred_path} is {pred.shape[1]} x {pred.shape[0]} px; the release image is "
                f"{truth.shape[1]} x {truth.shape[0]} px."
            )
        per_image.append(confusion(pred, truth))
    return score_record(root, split, per_image) | {"predictions": str(pred_dir)}


def score_record(root: Path, split: str, per_image: list[np.ndarray]) -> dict[str, Any]:
    """The results of scoring ``split`` of the release at ``root`` from each image's 2x2 confusion
    matrix: the release and its manifest hash, the metric definition, the split's confusion matrix,
    the split-level scores and the paper's per-image ones (the same record for every scorer)."""
    doc = read_manifest(root)
    cm = np.asarray(np.sum(per_image, axis=0, dtype=np.int64)) if per_image else np.zeros((2, 2), np.int64)
    return {
        "release": {
            "name": doc["name"],
            "version": doc["version"],
            "manifest_sha256": hashlib.sha256((Path(root) / MANIFEST).read_bytes()).hexdigest(),
        },
        "split": split,
        "images": len(per_image),
        "metric_definition": METRIC_DEFINITION,
        "confusion": cm.tolist(),
        "scores": scores(cm).to_dict(),
        "scores_per_image": per_image_scores(per_image),
    }
