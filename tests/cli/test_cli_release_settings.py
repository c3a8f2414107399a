"""Release settings as users set them: stored with the site (`site create/update/show`), used by
`release build` (auto scale and point size from the cameras), refused under the image-size floor,
and a build with nothing new is "up to date" (exit 0, nothing written). Runs the installed executable."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from sitehelpers import SYNTH, epoch_dirs, make_home, manifest_doc, run_cli

from siteline.catalog import open_catalog
from siteline.catalog.context import StageContext
from siteline.ingest.stage import ingest_mission
from siteline.pointpass import TilingResources
from siteline.tiles.stage import tile_scene

EXE = str(Path(sys.executable).with_name("siteline"))


def _exe(settings, *argv: str) -> subprocess.CompletedProcess:
    env = os.environ | {"SITELINE_HOME": str(settings.home), "SITELINE_DATABASE_URL": settings.database_url,
                        "COLUMNS": "200"}  # fmt: skip
    return subprocess.run([EXE, *argv], capture_output=True, text=True, env=env, timeout=600)


def test_site_settings_are_stored_shown_updated_and_checked(home, capsys) -> None:
    assert run_cli(capsys, "init")[0] == 0
    origin = [str(v) for v in SYNTH.origin]
    code, _, err = run_cli(capsys, "site", "create", "s", "--crs", SYNTH.crs, "--origin", *origin,
                           "--views", "40", "--scale", "auto", "--min-valid", "0.3")  # fmt: skip
    assert code == 0, err
    code, out, _ = run_cli(capsys, "site", "show", "s", "--json")
    record = json.loads(out)
    assert record["release_settings"] == {"pair": {"views": 40, "scale": "auto", "min_valid": 0.3}}
    assert "no registered camera" in record["release_now"]  # auto needs a scene's cameras
    code, out, err = run_cli(capsys, "site", "update", "s", "--preset", "fast", "--unset", "views", "--json")
    assert code == 0, err
    assert json.loads(out)["release_settings"] == {
        "preset": "fast",
        "pair": {"scale": "auto", "min_valid": 0.3},
    }
    code, out, err = run_cli(
        capsys,
        "site",
        "update",
        "s",
        "--no-trim-edges",
        "--splat-factor",
        "1.5",
        "--surface-probe",
        "0",
        "--change-views",
        "3",
        "--no-unsure-edges",
        "--no-sparse-surfaces",
        "--json",
    )
    assert code == 0, err
    assert json.loads(out)["release_settings"]["pair"] == {
        "scale": "auto", "min_valid": 0.3, "trim_edges": False, "splat_factor": 1.5, "surface_probe": 0.0,
        "view_params": {"change_views": 3}, "unsure_edges": False, "sparse_surfaces": False,
    }  # fmt: skip
    for bad, message in ((["--views", "0"], "views"), (["--scale", "big"], "--scale 'big'"),
                         (["--unset", "hue"], "not a release setting"), (["--preset", "turbo"], "unknown preset"),
                         (["--surface-probe", "1.2"], "surface_probe 1.2"),
                         (["--change-views", "-1"], "change_views must be a number of views")):  # fmt: skip
        code, _, err = run_cli(capsys, "site", "update", "s", *bad)
        assert code == 2 and message in err, err
    assert (
        json.loads(run_cli(capsys, "site", "show", "s", "--json")[1])["release_settings"]["preset"] == "fast"
    )


@pytest.mark.slow  # over 25 s on a 2-core machine: `make test-all` runs it
def test_release_build_uses_the_site_settings_and_is_up_to_date_once_built(tmp_path, synth_site) -> None:
    settings = make_home(tmp_path, site_dir=synth_site)
    cat = open_catalog(settings)
    for m in epoch_dirs(synth_site)[:2]:
        tile_scene(
            StageContext(cat, settings),
            ingest_mission(StageContext(cat, settings), m, "demo").scene_id,
            resources=TilingResources(workers=1),
        )
    cat.dispose()
    done = _exe(
        settings, "site", "update", "demo", "--views", "2", "--min-coverage", "0.1", "--min-valid", "0"
    )
    assert done.returncode == 0, done.stderr
    shown = json.loads(_exe(settings, "site", "show", "demo", "--json").stdout)["release_now"]
    assert (shown["scale"], shown["point_size_px"], shown["views"]) == (0.78, 5, 2)

    first = _exe(settings, "release", "build", "--site", "demo", "--name", "s", "--publish", "--json")
    assert first.returncode == 0, first.stderr
    info = json.loads(first.stdout)
    assert (info["version"], info["status"], info["reason"]) == ("1.0.0", "published", "first version")
    doc = manifest_doc(Path(info["root"]))
    assert doc["lineage"]["release_params"]["derived"]["scale"].startswith("auto: 512 px long side")
    assert all(max(it["size_px"]) >= 512 for it in doc["items"])  # 515 x 386 renders
    before = sorted((settings.home / "releases").rglob("*"))

    again = _exe(settings, "release", "build", "--site", "demo", "--name", "s", "--publish")
    assert again.returncode == 0, again.stderr
    assert "release s is up to date: 1.0.0 (published)" in again.stdout
    small = _exe(settings, "release", "build", "--site", "demo", "--name", "s", "--scale", "0.25")
    assert (
        small.returncode == 2 and "165 x 124 px" in small.stderr and "under the 256 px floor" in small.stderr
    )
    assert sorted((settings.home / "releases").rglob("*")) == before  # nothing written by either

    assert _exe(settings, "site", "update", "demo", "--point-size", "3").returncode == 0
    bumped = _exe(settings, "release", "build", "--site", "demo", "--name", "s", "--json")
    assert bumped.returncode == 0, bumped.stderr
    info = json.loads(bumped.stdout)
    assert (info["version"], info["status"], info["reason"]) == ("2.0.0", "draft", "point_size_px 5 -> 3")
