"""A full disk ends a command with one line naming the file system and its free space, exit 1, and
leaves nothing half-written: SITELINE_HOME on a small tmpfs the test mounts (skipped where mounting
is not allowed), filled at the blob copy, the catalog commit and the tile writes of an ingest."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from realdata import AUTZEN

EXE = Path(sys.executable).parent / "siteline"


@pytest.fixture
def small_fs(tmp_path):
    mnt = tmp_path / "small"
    mnt.mkdir()

    def mount(size: str) -> Path:
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mnt)], capture_output=True)
        if r.returncode != 0:
            # mounting needs root; tests/test_diskspace.py covers the same code without a mount
            pytest.skip(f"cannot mount a tmpfs here (needs root): {r.stderr.decode().strip()}")
        return mnt

    yield mount
    subprocess.run(["umount", str(mnt)], capture_output=True)


def _run(home: Path, *argv: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SITELINE_", "PREFECT_API"))}
    return subprocess.run([str(EXE), *argv], env=env | {"SITELINE_HOME": str(home)}, capture_output=True,
                          text=True, timeout=300)  # fmt: skip


# sizes that fill the disk during the blob copy and partition, the catalog commit, and the tile writes
# (`make test` runs the catalog case, `make test-all` all three)
@pytest.mark.parametrize(
    "size", [pytest.param("1500k", marks=pytest.mark.slow), "4500k", pytest.param("6m", marks=pytest.mark.slow)]
)
def test_a_full_disk_is_one_line_and_leaves_nothing(small_fs, size) -> None:
    home = small_fs(size) / "home"
    assert _run(home, "init").returncode == 0
    assert _run(home, "site", "create", "a", "--crs", "EPSG:32610", "--origin", "493000", "4878000", "130").returncode == 0
    r = _run(home, "ingest", str(AUTZEN), "--site", "a", "--captured-at", "2020-01-01T00:00:00Z")
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr and "error: the disk is full" in r.stderr, r.stderr
    assert f"the file system holding {home}" in r.stderr and "MB free" in r.stderr
    left = [p for p in home.rglob("*") if any(t in p.name for t in (".partial", ".tmp-", ".new-"))]
    assert left == [], left
    assert not [p for p in (home / "stores" / "tiles").rglob("*") if p.is_file()]  # no tile store
    listing = _run(home, "scene", "list", "--site", "a", "--json")
    scenes = json.loads(listing.stdout)["scenes"]
    blobs = [p for p in (home / "stores").rglob("*") if p.is_file()]
    if scenes:  # the disk filled while tiling: the scene stays registered, its files kept for `scene tile`
        assert [s["status"] for s in scenes] == ["registered"] and blobs
    else:  # while ingesting: nothing of the mission is kept
        assert blobs == []
