"""Scoring anyone's predictions against a release's ignore-aware truth (one confusion matrix)."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import NotRequired, TypedDict

import numpy as np
from PIL import Image

from siteline.errors import ReleaseError
from siteline.records.release import ReleaseItem
from siteline.release.export import prediction_names
from siteline.release.layout import ignore_aware_folder
from siteline.release.manifest import MANIFEST, METRIC_DEFINITION, read_manifest
from siteline.release.metrics import confusion, per_image_scores, scores
from siteline.schema import JSON


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


def find_predictions(pred_dir: Path, split: str, items: list[ReleaseItem]) -> dict[str, Path]:
    """Item id -> its prediction file: ``<id>.png`` or the name any export profile gave the item
    (``test_<id>.png`` for TorchGeo, the lower-cased id for torchange). ReleaseError names the
    missing ones."""
    present = {p.name: p for p in pred_dir.iterdir() if p.is_file()}
    found, missing = {}, []
    for it in items:
        name = next((n for n in prediction_names(split, it.id) if n in present), None)
        if name is None:
            missing.append(it.id)
        else:
            found[it.id] = present[name]
    if missing:
        raise ReleaseError(
            f"prediction folder {pred_dir} lacks {len(missing)} of {len(items)} {split} images. Each is found "
            f"by its id or the name an export gave it; e.g. {missing[0]} as {' or '.join(prediction_names(split, missing[0]))}."
        )
    return found


class ScoreRecord(TypedDict):
    """A split's scores (``siteline release score``, ``siteline evaluate``): the release (name, version,
    manifest sha256), the split, its image count, the metric definition, the 2 x 2 confusion matrix,
    split-level and per-image scores; a model's evaluation adds its checkpoint, name and the scores
    of predicting every pixel unchanged."""

    release: dict[str, str]
    split: str
    images: int
    metric_definition: dict[str, JSON]
    confusion: list[list[int]]
    scores: dict[str, float | int | None]
    scores_per_image: dict[str, float | int | None]
    checkpoint: NotRequired[str]
    model: NotRequired[str]
    trivial_scores: NotRequired[dict[str, float | int | str | None]]
    predictions: NotRequired[str]
    pred_size: NotRequired[tuple[int, int] | None]


def parse_size(text: str) -> tuple[int, int]:
    """(width, height) of ``WxH`` pixels."""
    w, sep, h = text.lower().partition("x")
    if not sep or not w.isdigit() or not h.isdigit() or int(w) < 1 or int(h) < 1:
        raise ReleaseError(f"size {text!r}: write WIDTHxHEIGHT in pixels, e.g. 256x256.")
    return int(w), int(h)


def score_predictions(
    root: Path, split: str, pred_dir: Path, pred_size: tuple[int, int] | None = None
) -> ScoreRecord:
    """Scores of the prediction PNGs in ``pred_dir`` against ``split`` of the release at ``root``.

    Every item of the split needs a prediction (:func:`find_predictions`) of the stored (padded)
    size, or of ``pred_size`` (width, height) when the tool resized the images (ChangeFormer: 256 x
    256), then brought back to the stored size by nearest neighbour; the truth's 255 pixels (ignore,
    padding) are excluded. Raises :class:`ReleaseError` naming missing or mis-sized files."""
    root, pred_dir = Path(root), Path(pred_dir)
    doc = read_manifest(root)
    if split not in ("train", "val", "test"):
        raise ReleaseError(f"split {split!r} is not one of train, val, test.")
    if not pred_dir.is_dir():
        raise ReleaseError(f"prediction folder {pred_dir} does not exist.")
    items = doc.items_of(split)
    if not items:
        raise ReleaseError(f"release {doc.title} has no {split} images.")
    paths = find_predictions(pred_dir, split, items)
    folder = ignore_aware_folder(doc)
    per_image = []
    for it in items:
        truth = np.asarray(Image.open(root / split / folder / f"{it.id}.png"), dtype=np.int64)
        pred = _sized(read_prediction(paths[it.id]), paths[it.id], truth.shape, pred_size)
        per_image.append(confusion(pred, truth))
    record = score_record(root, split, per_image)
    record["predictions"], record["pred_size"] = str(pred_dir), pred_size
    return record


def _sized(
    pred: np.ndarray, path: Path, shape: tuple[int, ...], pred_size: tuple[int, int] | None
) -> np.ndarray:
    want = (shape[1], shape[0]) if pred_size is None else pred_size
    if (pred.shape[1], pred.shape[0]) != want:
        raise ReleaseError(
            f"prediction {path} is {pred.shape[1]} x {pred.shape[0]} px; expected {want[0]} x {want[1]} px"
            + (
                " (the release image; give --pred-size WxH if your tool resized it)."
                if pred_size is None
                else "."
            )
        )
    if pred_size is None:
        return pred
    back = Image.fromarray(pred.astype(np.uint8)).resize((shape[1], shape[0]), Image.Resampling.NEAREST)
    return np.asarray(back, dtype=np.int64)


def score_record(root: Path, split: str, per_image: list[np.ndarray]) -> ScoreRecord:
    """The results of scoring ``split`` of the release at ``root`` from each image's 2x2 confusion
    matrix: the release and its manifest hash, the metric definition, the split's confusion matrix,
    the split-level scores and the paper's per-image ones (the same record for every scorer)."""
    doc = read_manifest(root)
    cm = np.asarray(np.sum(per_image, axis=0, dtype=np.int64)) if per_image else np.zeros((2, 2), np.int64)
    return {
        "release": {
            "name": doc.name,
            "version": doc.version,
            "manifest_sha256": hashlib.sha256((Path(root) / MANIFEST).read_bytes()).hexdigest(),
        },
        "split": split,
        "images": len(per_image),
        "metric_definition": METRIC_DEFINITION,
        "confusion": cm.tolist(),
        "scores": scores(cm).to_dict(),
        "scores_per_image": per_image_scores(per_image),
    }
