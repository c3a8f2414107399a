"""The installed ``siteline`` executable, run as a script would: 0 on success, 1 when a command
reports a failure, 2 on a bad request, for one error of every command group."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from sitehelpers import EXE, run_exe


@pytest.fixture(scope="module")
def exe_home(tmp_path_factory) -> Path:
    home = tmp_path_factory.mktemp("exe") / "home"
    proc = run_exe(home, "init")
    assert proc.returncode == 0, proc.stderr
    return home


BAD_REQUESTS = {
    "site": (["site", "show", "nosuch"], "unknown site 'nosuch'"),
    "db": (["db", "upgrade", "--bogus"], "No such option: --bogus"),
    "render": (["render", "missing.las", "--camera", "missing.json", "--out", "r"], "missing.json"),
    "views": (["views", "generate", "--bogus"], "No such option"),
    "synth": (["synth", "site", "--out", "s", "--density", "-3"], "density -3.0"),
    "ingest": (["ingest", "missing-mission", "--site", "nosuch"], "unknown site 'nosuch'"),
    "mission": (["mission", "list", "--site", "nosuch"], "unknown site 'nosuch'"),
    "scene": (["scene", "show", "99"], "no scene with id 99"),
    "photo": (["photo", "inspect", "missing.jpg"], "missing.jpg"),
    "labels": (["labels", "import", "1", "fixed.laz"], "labels file fixed.laz does not exist"),
    "release": (["release", "show", "nosuch", "1.0.0"], "no release nosuch 1.0.0"),
    "train": (["train", "--release", "nosuch", "--version", "1.0.0", "--out", "t"], "no release nosuch"),
    "evaluate": (
        ["evaluate", "--release", "nosuch", "--version", "1.0.0", "--checkpoint", "c", "--out", "e"],
        "no release nosuch",
    ),
    "bench": (["bench", "trade", "--site-density", "-1", "--out", "b"], "density -1.0"),
    "demo": (["demo", "--epochs", "0"], "epochs must be between 1 and 12"),
    "watch": (["watch", "missing", "--site", "nosuch", "--once"], "PREFECT_API_URL"),
}


@pytest.fixture(scope="module")
def bad_request_runs(exe_home, tmp_path_factory) -> dict[str, tuple[int, str, str]]:
    """Every bad request run at once (each is a separate process start-up, ~2 s of imports)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("SITELINE_")}
    env |= {"SITELINE_HOME": str(exe_home), "PREFECT_API_URL": ""}
    procs = {
        group: subprocess.Popen(
            [str(EXE), *argv],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            cwd=tmp_path_factory.mktemp(group),
        )
        for group, (argv, _) in BAD_REQUESTS.items()
    }
    out = {}
    for group, proc in procs.items():
        stdout, stderr = proc.communicate(timeout=300)
        out[group] = (proc.returncode, stdout, stderr)
    return out


@pytest.mark.parametrize("group", sorted(BAD_REQUESTS))
def test_bad_request_exits_2_with_one_clear_line(bad_request_runs, group) -> None:
    code, stdout, stderr = bad_request_runs[group]
    assert code == 2, (code, stdout[-500:], stderr[-2000:])
    assert BAD_REQUESTS[group][1] in stderr
    assert "Traceback" not in stderr


def test_init_with_an_unknown_database_driver_exits_2(tmp_path) -> None:
    proc = run_exe(tmp_path / "home", "init", env={"SITELINE_DATABASE_URL": "bogus://x"})
    assert proc.returncode == 2 and "no database driver" in proc.stderr and "Traceback" not in proc.stderr


def test_version_exits_0(tmp_path) -> None:
    proc = run_exe(tmp_path / "home", "--version")
    assert proc.returncode == 0 and proc.stdout.strip()


def test_catalog_commands_start_light(exe_home) -> None:
    """Only rendering commands import torch: listing scenes loads neither torch nor the pipeline, so
    `siteline scene list` and `siteline ingest --help` start in about a second."""
    code = (
        "import sys\nfrom siteline.cli import main\n"
        "rc = main(['scene', 'list', '--site', 'nosuch'])\n"
        "print(rc, sorted(m for m in ('torch', 'siteline.pipeline', 'siteline.render.zbuffer') if m in sys.modules))\n"
    )
    env = {k: v for k, v in os.environ.items() if not k.startswith("SITELINE_")} | {
        "SITELINE_HOME": str(exe_home)
    }
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert proc.stdout.strip().splitlines()[-1] == "2 []", proc.stdout + proc.stderr
    help_ = run_exe(exe_home, "ingest", "--help")
    assert help_.returncode == 0 and "--captured-at" in help_.stdout
    # a command's help loads none of the heavy libraries (issue 25: `ingest --help` under 1.5 s)
    code = (
        "import sys\nfrom siteline.cli import main\n"
        "try:\n    main(['ingest', '--help'])\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in ('torch', 'zarr', 'alembic', 'siteline.pipeline') if m in sys.modules))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert proc.stdout.strip().splitlines()[-1] == "[]", proc.stdout + proc.stderr
