"""Every ignored pixel of a release is accounted for: each item says why its pixels are ignore (the
causes and the valid share add up to its rendered pixels, as its label_ignore image counts them),
and stats.json, the datasheet and `release show` add them up with the padding."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from siteline.codes import IGNORE, IGNORE_CAUSES, RELEASE_IGNORE_CAUSES
from siteline.pairs.render import ignore_causes, small_gaps
from siteline.render.zbuffer import RenderResult


def _items(root: Path) -> list[dict]:
    return json.loads((root / "manifest.json").read_text())["items"]


def test_each_item_accounts_for_its_ignored_pixels(built) -> None:
    _, _, pub = built
    root = Path(pub.root)
    items = _items(root)
    assert items
    for it in items:
        assert set(it["ignore"]) == set(IGNORE_CAUSES)
        w, h = it["size_px"]
        label = np.asarray(Image.open(root / it["split"] / "label_ignore" / f"{it['id']}.png"))[:h, :w]
        ignored = float((label == IGNORE).mean())
        assert sum(it["ignore"].values()) == pytest.approx(ignored, abs=1e-9)
        assert it["valid"] + sum(it["ignore"].values()) == pytest.approx(1.0, abs=1e-9)
        assert 0.0 <= it["filled"] <= 1.0


def test_stats_split_the_ignore_share_by_cause(built) -> None:
    _, _, pub = built
    root = Path(pub.root)
    stats = json.loads((root / "stats.json").read_text())
    ig = stats["ignore"]
    total = sum(v["unchanged"] + v["changed"] + v["ignore"] for v in stats["class_balance"].values())
    counted = sum(v["ignore"] for v in stats["class_balance"].values())
    assert ig["share"] == pytest.approx(counted / total)
    assert set(ig["causes"]) == set(RELEASE_IGNORE_CAUSES)
    assert sum(ig["causes"].values()) == pytest.approx(ig["share"], abs=1e-6)
    assert ig["causes"]["unaccounted"] == pytest.approx(0.0, abs=1e-6)
    assert ig["causes"]["padding"] > 0  # the small site's renders are padded to multiples of 32
    assert sum(ig["causes_of_rendered"].values()) == pytest.approx(ig["share_of_rendered"], abs=1e-6)
    for split, s in ig["per_split"].items():
        assert sum(s["causes"].values()) == pytest.approx(s["share"], abs=1e-6), split
    readme = (root / "README.md").read_text()
    assert "## Where the ignore pixels come from" in readme
    assert "a gap between points in one scene" in readme and "padding to the stored size" in readme


def test_release_show_states_the_causes(built) -> None:
    settings, _, pub = built
    env = {"SITELINE_HOME": str(settings.home), "PATH": str(Path(__import__("sys").executable).parent)}
    out = subprocess.run(
        ["siteline", "release", "show", "rel", pub.version, "--json"], capture_output=True, text=True, env=env
    )
    assert out.returncode == 0, out.stderr
    shown = json.loads(out.stdout)["ignore"]
    stats = json.loads((Path(pub.root) / "stats.json").read_text())["ignore"]
    assert shown["causes"] == pytest.approx(stats["causes"])


def _render(hit: np.ndarray, change: np.ndarray) -> RenderResult:
    h, w = hit.shape
    return RenderResult(
        camera=None,  # type: ignore[arg-type]
        hit=hit,
        depth=np.where(hit, 1.0, np.nan),
        index=np.where(hit, 0, -1),
        attributes={"change": change},
    )


def test_causes_on_a_hand_made_view() -> None:
    """Sky on top (no surface in either), a one-pixel gap in A, a block only B shows, a pixel of an
    ignored class, one outside the fence, one whose place B's scan did not observe (and one such
    whose other side changed: changed), and one the edge rule made unsure."""
    h, w = 12, 12
    hit_a = np.ones((h, w), bool)
    hit_a[:3] = False  # sky
    hit_b = hit_a.copy()
    hit_a[6, 6] = False  # a gap between A's points
    hit_a[9:, 9:] = False  # B shows a surface A does not have
    change_a = np.zeros((h, w), np.uint8)
    change_b = np.zeros((h, w), np.uint8)
    change_b[4, 1] = 255  # an ignored class
    change_b[4, 2] = 255  # ... outside the fence
    change_a[7, 3] = 254  # B did not observe A's point's place
    change_a[7, 5], change_b[7, 5] = 254, 1  # ... but B's own point there changed
    outside = np.zeros((h, w), bool)
    outside[4, 2] = True
    from siteline.pairs.render import pair_mask

    mask = pair_mask(hit_a, change_a, hit_b, change_b)
    unsure = np.zeros((h, w), bool)
    unsure[10, 2] = True  # a farther surface drawn where a nearer one of other change may lie
    mask[unsure] = IGNORE
    causes = ignore_causes(_render(hit_a, change_a), _render(hit_b, change_b), mask, outside, unsure)
    n = h * w
    assert small_gaps(hit_a)[6, 6] and not small_gaps(hit_a)[0, 0]
    assert mask[7, 5] == 1 and mask[7, 3] == 255
    assert causes == pytest.approx(
        {
            "no_surface": 36 / n,
            "gap": 1 / n,
            "one_side": 9 / n,
            "outside_fence": 1 / n,
            "not_observed": 1 / n,
            "unsure_edge": 1 / n,
            "ignored_class": 1 / n,
        }
    )
