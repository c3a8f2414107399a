"""A pair's masks scored against the analytic truth of the synthetic site they were made from.

The pair's outputs give each view's camera (summary.json) and mask (label/, 0/1/255, the release's
``label_ignore/`` before padding); the site's ``truth/site.json`` gives the model that made its
epochs, whose surfaces are ray-cast (siteline.synth.viewtruth)."""

from __future__ import annotations

import io
import json
from collections.abc import Callable, Collection, Sequence
from pathlib import Path

import numpy as np
from PIL import Image

from siteline.errors import SynthError
from siteline.records.pairs import RenderedView
from siteline.stores import Store, join
from siteline.synth.model import NOISE, SNOW, SiteModel
from siteline.synth.primitives import Primitive
from siteline.synth.viewtruth import MaskScore, ViewTruth, view_truth

# LAS codes of the synthetic site whose classes the default taxonomy ignores
IGNORED_CODES = (SNOW, NOISE)


def site_model(site_dir: Path) -> tuple[SiteModel, list[list[float]]]:
    """The model that wrote the synthetic site at ``site_dir`` and its fence (site-local ring)."""
    path = Path(site_dir) / "truth" / "site.json"
    try:
        doc = json.loads(path.read_text())
        cfg = doc["config"]
        model = SiteModel(
            seed=cfg["seed"], n_epochs=cfg["epochs"], snow_epochs=tuple(cfg["snow_epochs"]),
            projection_error_epochs=tuple(cfg["projection_error_epochs"]), layout=cfg.get("layout", "site"),
        )  # fmt: skip
        fence = [list(map(float, v)) for v in doc["fence_m"]]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SynthError(f"{path}: not a synthetic site's truth ({exc}).") from exc
    return model, [*fence, fence[0]]


def score_views(
    views: Sequence[tuple[RenderedView, np.ndarray]],
    scale: float,
    first: Sequence[Primitive],
    second: Sequence[Primitive],
    fence: Sequence[Sequence[float]] | None,
    ignored_codes: Collection[int] = IGNORED_CODES,
    keep: Callable[[RenderedView, np.ndarray, ViewTruth], None] | None = None,
) -> MaskScore:
    """Every (view, mask) scored against the truth ray-cast through the view's camera at ``scale``;
    ``keep`` is given each view, its mask and its truth (to save pictures, say)."""
    score = MaskScore()
    for view, mask in views:
        truth = view_truth(view.camera.scaled(scale), first, second, ignored_codes, fence)
        score.add(mask, truth)
        if keep is not None:
            keep(view, mask, truth)
    return score


def pair_views(store: Store, root: str) -> tuple[list[tuple[RenderedView, np.ndarray]], float]:
    """A pair output's views with their masks, and the render scale, read from ``store`` at ``root``."""
    summary = json.loads(store.read_bytes(join(root, "summary.json")))
    views = [RenderedView.from_dict(v) for v in summary["views"]]
    masks = [np.asarray(Image.open(io.BytesIO(store.read_bytes(join(root, "label", v.file))))) for v in views]
    return list(zip(views, masks, strict=True)), float(summary["params"]["scale"])


def score_pair(
    store: Store,
    root: str,
    site_dir: Path,
    epochs: tuple[int, int],
    keep: Callable[[RenderedView, np.ndarray, ViewTruth], None] | None = None,
) -> MaskScore:
    """The masks of the pair output at ``root`` scored against the synthetic site at ``site_dir``,
    whose epochs ``epochs`` (t1, t2) the pair's scenes are."""
    model, fence = site_model(site_dir)
    views, scale = pair_views(store, root)
    return score_views(
        views, scale, model.primitives(epochs[0]), model.primitives(epochs[1]), fence, keep=keep
    )
