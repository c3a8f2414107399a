"""Operator mistakes and tampered releases end in one line, never a traceback (the installed
executable, as a user runs it): an export of a release that differs from what was published, an
existing browser page, a port out of range, a bad SITELINE_PREVIEW_URL, an address beyond this
machine without --public, a destination that cannot be written."""

from __future__ import annotations

import json
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from sitehelpers import run_cli, run_exe


def _env(settings) -> dict[str, str]:  # noqa: ANN001
    return {"SITELINE_DATABASE_URL": settings.database_url}


def test_an_export_of_a_tampered_release_is_refused_in_one_line(built, tmp_path) -> None:
    settings, _, pub = built
    manifest = Path(pub.root) / "manifest.json"
    original, mode = manifest.read_bytes(), manifest.stat().st_mode
    doc = json.loads(original)
    doc["splits"]["train"] = doc["splits"]["train"][1:]  # an edited split: one item dropped
    os.chmod(manifest, 0o644)
    try:
        manifest.write_text(json.dumps(doc))
        for profile in ("hf", "opencd"):
            r = run_exe(settings.home, "release", "export", "rel", pub.version, "--profile", profile,
                        "--out", str(tmp_path / profile), env=_env(settings))  # fmt: skip
            assert r.returncode == 2, (r.stdout, r.stderr)
            assert "differs from what was published" in r.stderr and "manifest.json" in r.stderr
            assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) <= 3
            assert not (tmp_path / profile).exists()
    finally:
        manifest.write_bytes(original)
        os.chmod(manifest, mode)
    ok = run_exe(settings.home, "release", "export", "rel", pub.version, "--profile", "opencd",
                 "--out", str(tmp_path / "fine"), env=_env(settings))  # fmt: skip
    assert ok.returncode == 0, ok.stderr


def test_browse_refuses_an_existing_page_unless_forced(built, tmp_path) -> None:
    settings, _, pub = built
    page = tmp_path / "mine.html"
    page.write_text("my notes")
    r = run_exe(
        settings.home, "release", "browse", "rel", pub.version, "--out", str(page), env=_env(settings)
    )
    assert r.returncode == 2 and "exists" in r.stderr and "--force" in r.stderr
    assert page.read_text() == "my notes"
    r = run_exe(
        settings.home,
        "release",
        "browse",
        "rel",
        pub.version,
        "--out",
        str(page),
        "--force",
        env=_env(settings),
    )
    assert r.returncode == 0, r.stderr
    assert "<html" in page.read_text().lower()


def test_bad_ports_urls_and_public_addresses_are_refused_in_one_line(tmp_path) -> None:
    home = tmp_path / "home"
    assert run_exe(home, "init").returncode == 0
    cases = (
        (["--port", "70000"], {}, "from 1 to 65535"),
        ([], {"SITELINE_PREVIEW_URL": "http://127.0.0.1:99999"}, "SITELINE_PREVIEW_URL"),
        ([], {"SITELINE_PREVIEW_URL": "http://127.0.0.1:0"}, "port 0: give one from 1 to 65535"),
        ([], {"SITELINE_PREVIEW_URL": "http://127.0.0.1:port"}, "SITELINE_PREVIEW_URL"),
        (["--host", "0.0.0.0"], {}, "--public"),
    )
    with ThreadPoolExecutor(len(cases)) as pool:  # each a process start-up: run them at once
        runs = list(pool.map(lambda c: run_exe(home, "previews", "serve", *c[0], env=c[1]), cases))
    for (argv, env, words), r in zip(cases, runs, strict=True):
        assert r.returncode == 2, (argv, env, r.stderr)
        assert words in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_a_destination_that_cannot_be_written_is_one_line_and_status_2(
    built, tmp_path, capsys, monkeypatch
) -> None:
    # run as root here, so a read-only folder is simulated where the page is written
    settings, _, pub = built
    from siteline.previews import browser

    def refuse(*_args, **_kwargs):  # noqa: ANN002, ANN003, ANN202
        raise PermissionError(13, "Permission denied", str(tmp_path / "ro" / "page.html"))

    monkeypatch.setenv("SITELINE_HOME", str(settings.home))
    monkeypatch.setenv("SITELINE_DATABASE_URL", settings.database_url)
    monkeypatch.setattr(browser, "browser_page", refuse)
    code, _, err = run_cli(
        capsys, "release", "browse", "rel", pub.version, "--out", str(tmp_path / "ro" / "page.html")
    )
    assert code == 2 and "cannot write" in err and "page.html" in err and "Permission denied" in err
    assert "Traceback" not in err
