"""Training and evaluating the FC-Siam-diff baseline on a release with the paper's set-up: SGD lr 1e-3,
momentum 0.9, weight decay 1e-4, polynomial decay (power 0.9), batch 4, class weights inversely
proportional to pixel counts, flips + colour jitter + crops, no rotation."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict

import numpy as np
import torch
from torch.utils.data import DataLoader

from siteline.baseline.model import FCSiamDiff, parameter_count
from siteline.data import ChangeDetectionDataset, TrainTransforms
from siteline.errors import ReleaseError
from siteline.release.manifest import read_manifest
from siteline.release.metrics import IGNORE, confusion, scores
from siteline.release.score import ScoreRecord, score_record
from siteline.schema import JSON


def class_weights(root: Path, split: str = "train") -> torch.Tensor:
    """Weights inversely proportional to the split's unchanged / changed pixel counts (stats.json)."""
    stats = json.loads((Path(root) / "stats.json").read_text())["class_balance"].get(split)
    if not stats:
        raise ReleaseError(f"release {root} has no {split} images.")
    counts = np.array([stats["unchanged"], stats["changed"]], dtype=np.float64) + 1.0
    w = counts.sum() / (2 * counts)
    return torch.tensor(w, dtype=torch.float32)


def _pad16(x: torch.Tensor, value: float = 0.0) -> torch.Tensor:
    h, w = x.shape[-2:]
    return torch.nn.functional.pad(x, (0, (-w) % 16, 0, (-h) % 16), value=value)


@dataclass(frozen=True)
class TrainParams:
    """A training run: ``epochs`` over the train split (or ``max_iters`` iterations when given),
    ``batch_size`` images of ``crop`` px squares at learning rate ``lr``, seeded by ``seed``, on the
    torch ``device``, with ``workers`` data-loading processes (0: in the training process)."""

    epochs: int = 1
    max_iters: int | None = None
    batch_size: int = 4
    lr: float = 1e-3
    crop: int = 256
    seed: int = 0
    device: str = "cpu"
    workers: int = 0


class TrainLog(TypedDict):
    """``train_log.json``: the release trained on, iterations, each iteration's loss, seconds, the
    model's parameter count and the training set-up."""

    release: str
    iterations: int
    losses: list[float]
    seconds: float
    parameters: int
    setup: dict[str, JSON]


def train(
    root: Path,
    out_dir: Path,
    config: TrainParams = TrainParams(),
    progress: Callable[[int, int, float], None] | None = None,
) -> TrainLog:
    """Train on the release's train split with ``config``; write ``model.pt`` and ``train_log.json``
    into ``out_dir``."""
    epochs, max_iters, batch_size, lr = config.epochs, config.max_iters, config.batch_size, config.lr
    crop, seed, device, workers = config.crop, config.seed, config.device, config.workers
    torch.manual_seed(seed)
    ds = ChangeDetectionDataset(root, "train", TrainTransforms(crop=crop, seed=seed))
    if len(ds) == 0:
        raise ReleaseError(f"release {root} has no training images.")
    loader = DataLoader(
        ds,
        batch_size=batch_size,
        shuffle=True,
        num_workers=workers,
        drop_last=len(ds) >= batch_size,
        generator=torch.Generator().manual_seed(seed),
        persistent_workers=workers > 0,
        # spawned, not forked: zarr and Prefect run threads a forked worker must not inherit
        multiprocessing_context="spawn" if workers > 0 else None,
    )
    model = FCSiamDiff().to(device)
    loss_fn = torch.nn.CrossEntropyLoss(weight=class_weights(root).to(device), ignore_index=IGNORE)
    opt = torch.optim.SGD(model.parameters(), lr=lr, momentum=0.9, weight_decay=1e-4)
    total = max_iters if max_iters is not None else epochs * len(loader)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda it: (1 - min(it, total - 1) / total) ** 0.9)
    losses, it, t0 = [], 0, time.perf_counter()
    model.train()
    while it < total:
        for batch in loader:
            img, mask = batch["image"].to(device), batch["mask"][:, 0].to(device)
            if (mask == IGNORE).all():
                continue
            loss = loss_fn(model(img), mask)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            losses.append(float(loss.detach()))
            it += 1
            if progress:
                progress(it, total, losses[-1])
            if it >= total:
                break
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    manifest = read_manifest(root)
    torch.save(
        {"model": model.state_dict(), "release": manifest.title},
        out_dir / "model.pt",
    )
    log: TrainLog = {
        "release": manifest.title,
        "iterations": it,
        "losses": losses,
        "seconds": time.perf_counter() - t0,
        "parameters": parameter_count(model),
        "setup": {
            "optimizer": "SGD",
            "lr": lr,
            "momentum": 0.9,
            "weight_decay": 1e-4,
            "poly_power": 0.9,
            "batch_size": batch_size,
            "crop": crop,
            "augment": ["crop", "hflip", "vflip", "colour jitter"],
            "seed": seed,
        },
    }
    (out_dir / "train_log.json").write_text(json.dumps(log, indent=1) + "\n")
    return log


@torch.no_grad()
def evaluate(
    root: Path, checkpoint: Path, out_json: Path, split: str = "test", device: str = "cpu"
) -> ScoreRecord:
    """Predict every image of ``split`` (padded to a multiple of 16), accumulate one confusion matrix,
    and write the scores with the release's manifest hash and the metric definition, beside those of
    predicting every pixel unchanged (``trivial_scores``: the floor a model that learned must clear)."""
    ckpt = torch.load(checkpoint, map_location=device, weights_only=True)
    model = FCSiamDiff().to(device)
    model.load_state_dict(ckpt["model"])
    model.eval()
    ds = ChangeDetectionDataset(root, split)
    if len(ds) == 0:
        raise ReleaseError(f"release {root} has no {split} images.")
    per_image = []
    for i in range(len(ds)):
        s = ds[i]
        h, w = s["mask"].shape[-2:]
        logits = model(_pad16(s["image"])[None].to(device))[..., :h, :w]
        per_image.append(confusion(logits.argmax(1)[0].cpu(), s["mask"][0]))
    result = score_record(root, split, per_image)
    result["checkpoint"], result["model"] = str(checkpoint), "FC-Siam-diff"
    # the floor a model must clear: every pixel predicted unchanged (mIoU about half the unchanged share)
    cm = np.asarray(result["confusion"], dtype=np.int64)
    trivial: dict[str, float | int | str | None] = {
        **scores(np.array([[cm[0].sum(), 0], [cm[1].sum(), 0]])).to_dict()
    }
    result["trivial_scores"] = trivial | {"predicts": "all unchanged"}
    Path(out_json).parent.mkdir(parents=True, exist_ok=True)
    Path(out_json).write_text(json.dumps(result, indent=1) + "\n")
    return result
