"""A full disk ends a command with one line naming the file system and its free space, exit 1, and
leaves nothing half-written: SITELINE_HOME on a small tmpfs the test mounts (skipped where mounting
is not allowed), filled at the blob copy, the catalog commit and the tile writes of an ingest."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from realdata import AUTZEN

EXE = Path(sys.executable).parent / "siteline"


@pytest.fixture
def small_fs(tmp_path):
    mnt = tmp_path / "small"
    mnt.mkdir()

    def mount(size: str) -> Path:
        r = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mnt)], capture_output=True
        )
        if r.returncode != 0:
            # mounting needs root; tests/stores/test_diskspace.py covers the same code without a mount
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
    "size",
    [pytest.param("1500k", marks=pytest.mark.slow), "4500k", pytest.param("6m", marks=pytest.mark.slow)],
)
def test_a_full_disk_is_one_line_and_leaves_nothing(small_fs, size) -> None:
    home = small_fs(size) / "home"
    _site(home)
    r = _run(home, "ingest", str(AUTZEN), "--site", "a", "--captured-at", "2020-01-01T00:00:00Z")
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr and "error: the disk is full" in r.stderr, r.stderr
    assert f"the file system holding {home}" in r.stderr and "MB free" in r.stderr
    left = _leftovers(home)
    assert left == [], left
    assert not [p for p in (home / "stores" / "tiles").rglob("*") if p.is_file()]  # no tile store
    listing = _run(home, "scene", "list", "--site", "a", "--json")
    scenes = json.loads(listing.stdout)["scenes"]
    blobs = [p for p in (home / "stores").rglob("*") if p.is_file()]
    if scenes:  # the disk filled while tiling: the scene stays registered, its files kept for `scene tile`
        assert [s["status"] for s in scenes] == ["registered"] and blobs
    else:  # while ingesting: nothing of the mission is kept
        assert blobs == []


def _site(home: Path) -> None:
    """A catalog at ``home`` and site ``a`` (autzen's frame)."""
    assert _run(home, "init").returncode == 0
    r = _run(home, "site", "create", "a", "--crs", "EPSG:32610", "--origin", "493000", "4878000", "130")
    assert r.returncode == 0, r.stderr


def _leftovers(home: Path) -> list[Path]:
    return [p for p in home.rglob("*") if any(t in p.name for t in (".partial", ".tmp-", ".new-"))]


def _tiles(home: Path) -> dict[str, str]:
    import hashlib

    root = home / "stores" / "tiles"
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in root.rglob("*")
        if p.is_file()
    }


def _status(home: Path) -> list[str]:
    return [
        s["status"] for s in json.loads(_run(home, "scene", "list", "--site", "a", "--json").stdout)["scenes"]
    ]


def test_retile_on_a_full_disk_or_stopped_leaves_the_old_store_and_nothing_else(small_fs) -> None:
    """`scene tile --retile` that fails (the disk fills; SIGTERM; SIGKILL of its process group) leaves
    the scene's current store as it was and no `.partial`: at once, or (SIGKILL) at the next run."""
    mnt = small_fs("40m")
    home = mnt / "home"
    _site(home)
    assert (
        _run(home, "ingest", str(AUTZEN), "--site", "a", "--captured-at", "2020-01-01T00:00:00Z").returncode
        == 0
    )
    before = _tiles(home)

    # the disk fills while the new store is written (it needs ~3 MB)
    filler = mnt / "filler"
    free_kb = os.statvfs(mnt).f_bavail * os.statvfs(mnt).f_frsize // 1024
    filler.write_bytes(b"\0" * ((free_kb - 1200) * 1024))
    r = _run(home, "scene", "tile", "1", "--retile", "--workers", "2")
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert r.stderr.count("error:") == 1 and "the disk is full" in r.stderr and "Traceback" not in r.stderr, (
        r.stderr
    )
    assert _leftovers(home) == [] and _tiles(home) == before and _status(home) == ["tiled"]
    filler.unlink()

    # stopped: SIGTERM (a service manager, a cancelled run) once the new store is being written
    for sig in (signal.SIGTERM, signal.SIGKILL):
        env = {k: v for k, v in os.environ.items() if not k.startswith(("SITELINE_", "PREFECT_API"))}
        p = subprocess.Popen([str(EXE), "scene", "tile", "1", "--retile", "--workers", "2"], env=env | {"SITELINE_HOME": str(home)},
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)  # fmt: skip
        deadline = time.monotonic() + 120
        while not any(".partial-" in q.name for q in (home / "stores" / "tiles").iterdir()):
            assert p.poll() is None, p.communicate()
            assert time.monotonic() < deadline, "the retile never started writing"
            time.sleep(0.02)
        if sig == signal.SIGTERM:
            p.send_signal(sig)
            _, err = p.communicate(timeout=120)
            assert p.returncode == 128 + sig, err
            assert "Traceback" not in err, err
            assert _leftovers(home) == [], "SIGTERM left what it was writing"
        else:
            os.killpg(p.pid, sig)  # the whole command, workers included, as a lost machine would
            p.communicate(timeout=120)
        assert _tiles(home) == before and _status(home) == ["tiled"]

    # the next run clears what the killed one left and tiles the scene again
    r = _run(home, "scene", "tile", "1", "--retile")
    assert r.returncode == 0, (r.stdout, r.stderr)
    assert _leftovers(home) == [] and _status(home) == ["tiled"]
    assert set(_tiles(home)) != set(before)  # a new generation's store replaced the old one
