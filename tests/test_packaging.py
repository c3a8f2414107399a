"""A non-editable install carries the contracts' schemas, the catalog migrations, the preview pages
with their vendored three.js, and the trade measurement (`siteline bench trade` needs no checkout)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

CHECK = """
import siteline, sqlalchemy as sa
assert siteline.__file__.startswith({target!r}), siteline.__file__
from siteline.schema import load_schema
from siteline.catalog.engine import make_engine
from siteline.catalog.migrate import upgrade
from siteline.site.taxonomy import default_taxonomy
assert load_schema("release.schema.json")["title"]
engine = make_engine("sqlite:///" + {target!r} + "/catalog.sqlite")
upgrade(engine)
assert "release" in sa.inspect(engine).get_table_names()
assert default_taxonomy().classes
from importlib.resources import files
static = files("siteline.previews").joinpath("static")
assert static.joinpath("browser.html").is_file() and static.joinpath("viewer.html").is_file()
assert static.joinpath("three", "three.module.js").is_file() and static.joinpath("three", "LICENSE").is_file()
import siteline.trade
assert siteline.trade.__file__.startswith({target!r}), siteline.trade.__file__
"""


@pytest.mark.slow  # builds and installs a wheel (about a minute); `make test-all` runs it
def test_wheel_install_finds_schemas_and_migrations(tmp_path) -> None:
    wheels, target, src = tmp_path / "wheels", tmp_path / "target", tmp_path / "src"
    # built from a copy of what the wheel is made of: setuptools leaves build/ beside the sources it builds
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, src / name)
    shutil.copytree(
        REPO / "platform", src / "platform", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info")
    )
    pip = [sys.executable, "-m", "pip", "-q"]
    subprocess.run(
        [*pip, "wheel", "--no-deps", "--no-build-isolation", str(src), "-w", str(wheels)],
        check=True,
        cwd=tmp_path,
    )
    # nothing written into the checkout (a build/ there, if any, is older than this test's copy)
    assert not (REPO / "build").exists() or (REPO / "build").stat().st_mtime < src.stat().st_mtime
    wheel = next(wheels.glob("siteline-*.whl"))
    subprocess.run([*pip, "install", "--no-deps", "--target", str(target), str(wheel)], check=True)
    env = {"PYTHONPATH": str(target), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    proc = subprocess.run(
        [sys.executable, "-c", CHECK.format(target=str(target))], env=env, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    # the installed command runs the trade (one variant, the defaults) on a tiny synthetic site, from a
    # folder with no checkout
    out = tmp_path / "trade"
    ran = subprocess.run(
        [sys.executable, "-m", "siteline", "bench", "trade", "--site-density", "10", "--views", "4",
         "--variant", "default={}", "--out", str(out)],
        env=env | {"SITELINE_HOME": str(tmp_path / "home")}, capture_output=True, text=True, cwd=tmp_path, timeout=1200,
    )  # fmt: skip
    assert ran.returncode == 0, ran.stderr[-2000:]
    [table] = out.rglob("trade.md")  # under out/<layout>-<density>/
    row = next(line for line in table.read_text().splitlines() if line.startswith("| default |"))
    assert "no release" not in row and float(row.split("|")[3]) > 0.5, row
