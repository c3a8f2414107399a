"""Releases follow label sets: each scene's newest unless pinned, versions in the lineage, a major
bump when they change, `release diff` names the change, and old pair outputs and releases stay."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from sitehelpers import manifest_doc, run_cli

from labelsets.edits import centre_box, export, versions
from siteline import pipeline
from siteline.catalog.context import StageContext
from siteline.errors import ImmutableError, LabelSetError
from siteline.labelsets.stage import ImportOptions, import_labels
from siteline.records.params.pairs import PairParams
from siteline.records.params.release import ReleaseKnobs
from siteline.records.release import ReleaseOptions
from siteline.release.stage import publish_release

# one candidate view per real camera: the test is about label sets, not the view sample (the one nadir
# view of this small site at scale 0.25 is 0.69-0.70 valid since the rims of a farther change are
# ignored, 0.72-0.73 before: the default min_valid 0.7 would leave the pair no view)
ONE = {"vertical_fractions": [1.0], "forward_fractions": [0.0], "mirror": False}
PARAMS = PairParams(
    scale=0.25, point_size_px=3, views=3, seed=0, min_coverage=0.2, min_valid=0.6, view_params=ONE
)
KNOBS = ReleaseKnobs.exactly(PARAMS, min_image_px=64)


def test_release_uses_new_label_set_and_bumps_major(scenes, tmp_path, capsys, monkeypatch) -> None:
    settings, cat = scenes
    pinned = {1: versions(cat, 1)[-1], 2: versions(cat, 2)[-1]}
    first = pipeline.release(
        StageContext(cat, settings),
        "demo",
        "lab",
        KNOBS,
        options=ReleaseOptions(label_sets=pinned, publish=True),
    )
    assert first.version == "1.0.0"

    las = export(cat, 1, tmp_path / "s1.las")
    cls = np.asarray(las.classification).copy()
    edit = centre_box(las, 20.0) & (cls != 255) & (cls != 5)
    cls[edit] = 5  # a fleet of vehicles appears in the correction
    las.classification = cls
    las.write(tmp_path / "s1_fixed.las")
    new = import_labels(
        StageContext(cat, settings), 1, tmp_path / "s1_fixed.las", ImportOptions(note="vehicles")
    )
    assert new.created

    second = pipeline.release(
        StageContext(cat, settings), "demo", "lab", KNOBS, options=ReleaseOptions(publish=True)
    )
    assert second.version == "2.0.0"  # a label set changed: major bump
    lineage = manifest_doc(second.root)["lineage"]
    scenes_ = {sc["id"]: sc for sc in lineage["scenes"]}
    assert scenes_[1]["label_set_version"] == new.version and scenes_[2]["label_set_version"] == pinned[2]
    assert scenes_[1]["label_set_sha256"] == new.source_sha256
    assert lineage["pairs"][0]["label_sets"] == {"t1": new.version, "t2": pinned[2]}
    old = manifest_doc(first.root)["lineage"]
    assert {sc["id"]: sc["label_set_version"] for sc in old["scenes"]} == pinned
    # the old pair outputs were not overwritten: both output folders are complete
    roots = sorted(
        p for p in (Path(settings.store.url) / "pairs" / "pair-1").iterdir() if not p.name.startswith(".")
    )
    assert len([r for r in roots if settings.store.is_complete(str(r))]) >= 2

    assert second.reason == f"scene 1 label set v{pinned[1]} -> v{new.version}"
    # the same inputs again: nothing is built or published, the latest version is up to date
    before = sorted((settings.home / "releases").rglob("*"))
    third = pipeline.release(
        StageContext(cat, settings), "demo", "lab", KNOBS, options=ReleaseOptions(publish=True)
    )
    assert (third.version, third.status, third.up_to_date) == ("2.0.0", "published", True)
    assert sorted((settings.home / "releases").rglob("*")) == before

    monkeypatch.setenv("SITELINE_HOME", str(settings.home))
    monkeypatch.setenv("SITELINE_DATABASE_URL", settings.database_url)
    code, out, _ = run_cli(capsys, "release", "diff", "lab", "1.0.0", "2.0.0", "--json")
    assert code == 0
    diff = json.loads(out)
    change = diff["label_sets"]["scenes"]
    assert list(change) == ["1"] and change["1"]["version"] == [pinned[1], new.version]
    assert change["1"]["source"][1] == "import s1_fixed.las"
    assert any(p.startswith("train/label/") or "/label/" in p for p in diff["files"]["changed"])
    code, out, _ = run_cli(capsys, "release", "verify", "lab", "1.0.0")
    assert code == 0
    with pytest.raises(ImmutableError):
        publish_release(StageContext(cat, settings), "lab", "2.0.0")

    # pinning a version that does not exist is refused before anything is built
    with pytest.raises(LabelSetError, match="no label-set version 42"):
        pipeline.release(
            StageContext(cat, settings), "demo", "lab", KNOBS, options=ReleaseOptions(label_sets={1: 42})
        )
