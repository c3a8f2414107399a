"""Change-detection metrics from one confusion matrix over a whole split (DESIGN.md §8).

Pixels labelled 255 are excluded. Reported: IoU per class, mIoU (mean of unchanged and changed IoU),
precision, recall and F1 of the changed class, overall accuracy, Cohen's kappa. Per-image averaging
gives very different numbers and is never reported.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch

from siteline.codes import IGNORE
from siteline.errors import LabelError


def confusion(
    pred: torch.Tensor | np.ndarray, target: torch.Tensor | np.ndarray, num_classes: int = 2
) -> np.ndarray:
    """(C, C) int64 counts, rows = target, columns = prediction, pixels where target is 255 skipped."""
    p = torch.as_tensor(pred).reshape(-1).long()
    t = torch.as_tensor(target).reshape(-1).long()
    keep = t != IGNORE
    p, t = p[keep], t[keep]
    if p.numel() and (p.min() < 0 or p.max() >= num_classes or t.max() >= num_classes):
        raise LabelError(f"labels must lie in [0, {num_classes}) or be {IGNORE}.")
    cm = torch.bincount(t * num_classes + p, minlength=num_classes * num_classes)
    return cm.reshape(num_classes, num_classes).cpu().numpy().astype(np.int64)


@dataclass
class Scores:
    """Split-level scores of one confusion matrix. An IoU is None when its class is absent from both
    truth and prediction (its union is empty); mIoU is the mean over the classes that are present, as
    torchmetrics' JaccardIndex does (a perfect prediction of an all-unchanged split scores mIoU 1).
    Precision, recall and F1 of an absent changed class are 0 (torchmetrics' ``zero_division=0``)."""

    iou_unchanged: float | None
    iou_changed: float | None
    miou: float
    precision: float
    recall: float
    f1: float
    oa: float
    kappa: float
    pixels: int

    def to_dict(self) -> dict[str, float | int | None]:
        return asdict(self)


def _div(a: float, b: float) -> float:
    return float(a / b) if b else 0.0


def scores(cm: np.ndarray) -> Scores:
    """Scores of a 2x2 confusion matrix (rows target, columns prediction; class 1 = changed)."""
    cm = np.asarray(cm, dtype=np.float64)
    tn, fp, fn, tp = cm[0, 0], cm[0, 1], cm[1, 0], cm[1, 1]
    n = cm.sum()
    iou0 = _div(tn, tn + fp + fn) if tn + fp + fn else None
    iou1 = _div(tp, tp + fp + fn) if tp + fp + fn else None
    present = [v for v in (iou0, iou1) if v is not None]
    precision = _div(tp, tp + fp)
    recall = _div(tp, tp + fn)
    f1 = _div(2 * precision * recall, precision + recall)
    oa = _div(tp + tn, n)
    pe = _div((tp + fp) * (tp + fn) + (tn + fn) * (tn + fp), n * n)
    kappa = _div(oa - pe, 1 - pe)
    miou = sum(present) / len(present) if present else 0.0
    return Scores(iou0, iou1, miou, precision, recall, f1, oa, kappa, int(n))


def per_image_scores(cms: list[np.ndarray]) -> dict[str, float | int | None]:
    """The paper's (Pylon's) convention: per image, the IoU of each class from that image's own 2x2
    confusion matrix, NaN when the class is absent from both the image's truth and prediction; each
    class's IoU is the mean over images ignoring NaN (nanmean); mIoU is the mean of the two classes.
    Differs from :func:`scores` (one matrix over the split) by a few points on real models."""
    ious = []
    for cm in cms:
        cm = np.asarray(cm, dtype=np.float64)
        tn, fp, fn, tp = cm[0, 0], cm[0, 1], cm[1, 0], cm[1, 1]
        u0, u1 = tn + fp + fn, tp + fp + fn
        ious.append((tn / u0 if u0 else np.nan, tp / u1 if u1 else np.nan))
    arr = np.array(ious, dtype=np.float64).reshape(-1, 2)
    per_class = [float(np.nanmean(arr[:, c])) if np.isfinite(arr[:, c]).any() else None for c in (0, 1)]
    present = [v for v in per_class if v is not None]
    return {
        "iou_unchanged": per_class[0],
        "iou_changed": per_class[1],
        "miou": float(np.mean(present)) if present else 0.0,
        "images": len(cms),
    }
