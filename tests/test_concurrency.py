"""Writers racing as users start them: the installed ``siteline`` run twice at once for the same work,
on SQLite and on PostgreSQL. Every run exits 0, nothing is lost or half-written, and the second run of
each pair finds what the first made (catalog locks, siteline.catalog.locks; partial folders owned by
their writer, siteline.stores.owners)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest
from sitehelpers import epoch_dirs, make_home

from siteline.catalog.context import StageContext

EXE = Path(sys.executable).with_name("siteline")


@pytest.fixture(scope="module")
def race_site(tmp_path_factory) -> Path:
    from siteline.synth import SynthParams, write_site

    out = tmp_path_factory.mktemp("race-site")
    write_site(out, SynthParams(epochs=2, density_pts_m2=2.0, seed=11))
    return out


def _env(settings) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("SITELINE_")}
    return env | {"SITELINE_HOME": str(settings.home), "SITELINE_DATABASE_URL": settings.database_url}


def _race(settings, *argvs: list[str]) -> list[subprocess.CompletedProcess]:
    """Start every command at once; wait for all."""
    procs = [
        subprocess.Popen(
            [str(EXE), *argv], env=_env(settings), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        for argv in argvs
    ]
    out = []
    for p, argv in zip(procs, argvs, strict=True):
        stdout, stderr = p.communicate(timeout=600)
        out.append(subprocess.CompletedProcess([str(EXE), *argv], p.returncode, stdout, stderr))
    return out


def _ok(runs: list[subprocess.CompletedProcess]) -> list[str]:
    for r in runs:
        assert r.returncode == 0, (r.args, r.stdout[-1000:], r.stderr[-3000:])
    return [r.stdout for r in runs]


# 34 s each on a 2-core machine: SQLite in `make test`, PostgreSQL in `make test-all`
@pytest.mark.parametrize(
    "db_url", ["sqlite", pytest.param("postgresql", marks=pytest.mark.slow)], indirect=True
)
def test_racing_writers_lose_nothing(race_site, tmp_path, db_url) -> None:
    from siteline.catalog import open_catalog
    from siteline.catalog.labelsets import label_sets, labelled_source
    from siteline.catalog.missions import list_missions
    from siteline.ingest.stage import ingest_mission
    from siteline.labelsets.export import export_label_set
    from siteline.labelsets.store import open_labelled
    from siteline.stores import open_store

    settings = make_home(tmp_path, db_url, race_site)
    e00, e01 = (str(p) for p in epoch_dirs(race_site))

    # the same mission dropped twice at once: ingested (and tiled) once, the other run says so
    outs = _ok(_race(settings, ["ingest", e00, "--site", "demo"], ["ingest", e00, "--site", "demo"]))
    assert (
        sum("ingested as scene 1" in o for o in outs) == 1 and sum("already ingested" in o for o in outs) == 1
    )
    cat = open_catalog(settings)
    with cat.transaction() as s:
        assert len(list_missions(s)) == 1

    # one scene tiled twice at once: tiled once, the other run finds nothing to do
    sid = ingest_mission(StageContext(cat, settings), Path(e01), "demo").scene_id
    outs = _ok(_race(settings, ["scene", "tile", str(sid)], ["scene", "tile", str(sid)]))
    assert sum(f"scene {sid} tiled" in o for o in outs) == 1 and sum("nothing to do" in o for o in outs) == 1

    # two releases of a pair nobody processed yet: the pair is processed once, whole
    build = ["release", "build", "--site", "demo", "--scale", "0.125", "--point-size", "3", "--views", "2",
             "--min-coverage", "0.1", "--min-valid", "0", "--min-image-px", "64", "--json"]  # fmt: skip
    outs = _ok(_race(settings, [*build, "--name", "a"], [*build, "--name", "b"]))
    roots = {json.loads(o)["root"] for o in outs}
    for name in ("a", "b"):
        assert _ok(_race(settings, ["release", "verify", name, "1.0.0"]))
    pair_dirs = [
        p for p in (Path(settings.store.url) / "pairs" / "pair-1").iterdir() if not p.name.startswith(".")
    ]
    assert len(pair_dirs) == 1 and len(roots) == 2  # one set of outputs, two releases drawn from it
    labels = next(p for p in (Path(settings.store.url) / "labels").iterdir() if not p.name.startswith("."))
    with cat.transaction() as s:
        tiles = [open_labelled(*labelled_source(s, sc)) for sc in (1, sid)]
    store = open_store(str(labels))
    for side, t in zip(("t1", "t2"), tiles, strict=True):  # every tile of both scenes has its change flags
        group = store.open_group(f"{labels}/{side}")
        assert sorted(group["tiles"].group_keys()) == sorted(t.by_tile)

    # two corrections of one scene, both exported from label set 1, imported at once: two versions,
    # both stores whole, and the second merges its changes onto the first's (none is undone)
    fixes, edited = [], []
    for k, cls in enumerate((4, 5)):
        export_label_set(cat, 1, tmp_path / f"s1_{k}.las")
        las = laspy.read(tmp_path / f"s1_{k}.las")
        codes = np.asarray(las.classification).copy()
        edited.append(
            np.flatnonzero(codes != 255)[200 * k : 200 * (k + 1)]
        )  # each file corrects other points
        codes[edited[-1]] = cls
        las.classification = codes
        las.write(tmp_path / f"s1_{k}_fixed.las")
        fixes.append(["labels", "import", "1", str(tmp_path / f"s1_{k}_fixed.las"), "--no-announce"])
    _ok(_race(settings, *fixes))
    with cat.transaction() as s:
        rows = label_sets(s, 1)
        assert [r.version for r in rows] == [1, 2, 3]
        assert rows[2].details["merged_from"] == 1 and rows[1].details["merged_from"] is None
        readers = [open_labelled(*labelled_source(s, 1, v)) for v in (2, 3)]
    for r in readers:
        assert all(len(r.read_tile(t, ("class",))) for t in r.by_tile)
    export_label_set(cat, 1, tmp_path / "s1_now.las")
    now = np.asarray(laspy.read(tmp_path / "s1_now.las").classification)
    assert (now[edited[0]] == 4).all() and (now[edited[1]] == 5).all()  # both corrections hold
    # a third correction from label set 1 that changes the first's points otherwise: refused, exit 2
    las = laspy.read(tmp_path / "s1_0.las")
    codes = np.asarray(las.classification).copy()
    codes[edited[0][:50]] = 7
    las.classification = codes
    las.write(tmp_path / "s1_clash.las")
    (clash,) = _race(settings, ["labels", "import", "1", str(tmp_path / "s1_clash.las"), "--no-announce"])
    assert clash.returncode == 2 and "changed 50 of the points it changes" in clash.stderr, clash.stderr
    with cat.transaction() as s:
        assert [r.version for r in label_sets(s, 1)] == [1, 2, 3]
    cat.dispose()
