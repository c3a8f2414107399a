"""Releases against forgery and crashes: verify checks the manifest against the catalog's record and
refuses symlinks; exports never write into a release or outside themselves; a publish or rebuild
killed at any point is mended by name (``siteline release repair``, or the next publish)."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from siteline import pipeline
from siteline.catalog.context import StageContext
from siteline.errors import ReleaseError
from siteline.release.export import export_release

from .conftest import KNOBS

EXE = Path(sys.executable).with_name("siteline")


def _exe(settings, *argv: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("SITELINE_")}
    env |= {"SITELINE_HOME": str(settings.home), "SITELINE_DATABASE_URL": settings.database_url}
    return subprocess.run([str(EXE), *argv], env=env, capture_output=True, text=True, timeout=300)


class Tamper:
    """Change files of a read-only published release and put them back exactly."""

    def __init__(self, root: Path) -> None:
        self.root, self.saved = Path(root), {}

    def write(self, rel: str, data: bytes) -> None:
        p = self.root / rel
        self.saved.setdefault(rel, (p.read_bytes(), p.stat().st_mode))
        os.chmod(p, 0o644)
        p.write_bytes(data)

    def symlink(self, rel: str) -> None:
        p = self.root / rel
        self.saved.setdefault(rel, (p.read_bytes(), p.stat().st_mode))
        os.chmod(self.root / Path(rel).parent, 0o755)
        copy = self.root.parent / f".{p.name}.copy"
        shutil.copyfile(p, copy)
        p.unlink()
        p.symlink_to(copy)

    def restore(self) -> None:
        for rel, (data, mode) in self.saved.items():
            p = self.root / rel
            if p.is_symlink():
                target = Path(os.readlink(p))
                p.unlink()
                target.unlink(missing_ok=True)
            p.write_bytes(data)
            os.chmod(p, mode)
            os.chmod(p.parent, 0o555)


def test_verify_catches_forged_manifests_and_symlinks(built) -> None:
    settings, _, pub = built
    root = Path(pub.root)
    manifest = json.loads((root / "manifest.json").read_text())
    image = next(f for f in manifest["files"] if f["path"].endswith(".png"))
    cases = {
        "edited field": lambda t: t.write(
            "manifest.json", (root / "manifest.json").read_bytes().replace(b'"created"', b'"created" ', 1)
        ),
        "forged image, entry updated": lambda t: _forge(t, root, manifest, image["path"]),
        "image swapped for a symlink": lambda t: t.symlink(image["path"]),
    }
    for what, act in cases.items():
        t = Tamper(root)
        try:
            act(t)
            bad = _exe(settings, "release", "verify", "rel", pub.version)
        finally:
            t.restore()
        assert bad.returncode == 1, (what, bad.stdout, bad.stderr)
        expect = (
            "a symlink" if "symlink" in what else "manifest.json: sha256 differs from the catalog's record"
        )
        assert expect in bad.stdout, (what, bad.stdout)
    assert _exe(settings, "release", "verify", "rel", pub.version).returncode == 0


def _forge(t: Tamper, root: Path, manifest: dict, rel: str) -> None:
    forged = (root / rel).read_bytes()[:-1] + b"\x00"
    t.write(rel, forged)
    doc = json.loads(json.dumps(manifest))
    entry = next(f for f in doc["files"] if f["path"] == rel)
    entry["size"], entry["sha256"] = len(forged), hashlib.sha256(forged).hexdigest()
    t.write("manifest.json", (json.dumps(doc, indent=1) + "\n").encode())


def test_exports_stay_out_of_releases_and_inside_themselves(built, tmp_path) -> None:
    settings, _, pub = built
    root = Path(pub.root)
    for inside in (root / "export", root / "train" / "x"):
        with pytest.raises(ReleaseError, match="is inside"):
            export_release(root, "opencd", inside, copy=True, protected=settings.home / "releases")
    (tmp_path / "link").symlink_to(root)
    with pytest.raises(ReleaseError, match="is inside"):
        export_release(root, "opencd", tmp_path / "link" / "out", protected=settings.home / "releases")
    assert not list(root.rglob("export")) and not (root / "train" / "x").exists()
    (tmp_path / "afile").write_text("mine")
    code = _exe(
        settings,
        "release",
        "export",
        "rel",
        pub.version,
        "--profile",
        "opencd",
        "--out",
        str(tmp_path / "afile"),
    )
    assert code.returncode == 2 and "is a file" in code.stderr and "Traceback" not in code.stderr
    (tmp_path / ".new.partial").mkdir()  # someone's folder beside --out new: not ours to delete
    export_release(root, "opencd", tmp_path / "new")
    assert (tmp_path / ".new.partial").is_dir() and (tmp_path / "new" / "siteline-export.json").is_file()
    # an item id that leaves the export (an edited manifest): refused before a file is copied
    evil = tmp_path / "evil-release"
    shutil.copytree(root, evil)
    doc = json.loads((evil / "manifest.json").read_text())
    doc["items"][0]["id"] = "../../../../evil"
    os.chmod(evil / "manifest.json", 0o644)
    (evil / "manifest.json").write_text(json.dumps(doc))
    with pytest.raises(ReleaseError, match="is not a file name"):
        export_release(evil, "opencd", tmp_path / "out-evil", copy=True)
    assert not (tmp_path / "out-evil").exists() and not list(tmp_path.parent.glob("evil*"))


KILL = """
import os, signal, sys
import siteline.release.stage as stage
target = sys.argv[1]
def die(*a, **k):
    os.kill(os.getpid(), signal.SIGKILL)
setattr(stage, target, die)
from siteline.cli import main
sys.exit(main(sys.argv[2:]))
"""


def _killed(settings, target: str, *argv: str) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("SITELINE_")}
    env |= {"SITELINE_HOME": str(settings.home), "SITELINE_DATABASE_URL": settings.database_url}
    proc = subprocess.run(
        [sys.executable, "-c", KILL, target, *argv], env=env, capture_output=True, text=True
    )
    assert proc.returncode == -signal.SIGKILL, proc.stderr[-2000:]


@pytest.mark.slow  # over 25 s on a 2-core machine: `make test-all` runs it
def test_a_killed_publish_or_rebuild_is_mended_by_name(built) -> None:
    settings, cat, _ = built
    for name in ("crash-a", "crash-b"):
        pipeline.release(StageContext(cat, settings), "demo", name, KNOBS)
    # killed after the move, before the catalog recorded it: the next publish finishes it
    _killed(settings, "record_published", "release", "publish", "crash-a", "1.0.0")
    final = settings.home / "releases" / "crash-a" / "1.0.0"
    assert final.is_dir()
    bad = _exe(settings, "release", "verify", "crash-a", "1.0.0")
    assert (
        bad.returncode == 1
        and "never recorded" in bad.stdout
        and "siteline release repair crash-a 1.0.0" in bad.stdout
    )
    again = _exe(settings, "release", "publish", "crash-a", "1.0.0")
    assert again.returncode == 0, again.stderr
    assert _exe(settings, "release", "verify", "crash-a", "1.0.0").returncode == 0
    assert not (final.stat().st_mode & 0o222)  # the version folder itself is read-only too
    # killed after the record, before the files were made read-only: the next publish finishes it too
    _killed(settings, "make_read_only", "release", "publish", "crash-b", "1.0.0")
    bad = _exe(settings, "release", "verify", "crash-b", "1.0.0")
    assert bad.returncode == 1 and "still writable" in bad.stdout
    fixed = _exe(settings, "release", "publish", "crash-b", "1.0.0")
    assert fixed.returncode == 0, fixed.stderr
    assert _exe(settings, "release", "verify", "crash-b", "1.0.0").returncode == 0
    # a draft rebuilt with fewer items (one pair of two), killed before its rows: publish refuses,
    # repair removes it
    pipeline.release(StageContext(cat, settings), "demo", "crash-c", KNOBS)
    fewer = ["release", "build", "--site", "demo", "--name", "crash-c", "--version", "1.0.0", "--scale", "0.5",
             "--point-size", "3", "--views", "6", "--min-coverage", "0.3", "--pairs", "1"]  # fmt: skip
    _killed(settings, "record_draft", *fewer)
    refused = _exe(settings, "release", "publish", "crash-c", "1.0.0")
    assert refused.returncode == 2 and "catalog's record" in refused.stderr, refused.stderr
    assert (
        "not the draft the catalog records" in _exe(settings, "release", "verify", "crash-c", "1.0.0").stdout
    )
    assert "removed" in _exe(settings, "release", "repair", "crash-c", "1.0.0").stdout
    assert _exe(settings, "release", "show", "crash-c", "1.0.0").returncode == 2
