"""Errors told by their codes, never by words a user's names may hold: a mission folder or a database
named with a full disk's wording gets its own error, not "the disk is full"; a catalog another writer
holds past the wait is one line and exit 1 (the installed executable, as a script runs it)."""

from __future__ import annotations

import sqlite3
import threading
import time

from sitehelpers import run_exe


def test_names_that_hold_full_disk_wording_get_their_real_error(tmp_path) -> None:
    home = tmp_path / "home"
    assert run_exe(home, "init").returncode == 0
    r = run_exe(home, "site", "create", "a", "--crs", "EPSG:32610", "--origin", "493000", "4878000", "130")
    assert r.returncode == 0, r.stderr
    missing = tmp_path / "15321 requested and 8763 written" / "mission"
    r = run_exe(home, "ingest", str(missing), "--site", "a")
    assert r.returncode == 2 and "disk is full" not in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert "15321 requested and 8763 written" in r.stderr  # the folder it could not find, named
    url = "postgresql+psycopg://postgres@127.0.0.1:5432/could not extend file"
    r = run_exe(home, "site", "list", env={"SITELINE_DATABASE_URL": url})
    assert r.returncode != 0 and "disk is full" not in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert "could not extend file" in r.stderr  # the database it could not reach, named


def test_a_catalog_held_past_the_wait_is_one_line_and_exit_1(tmp_path) -> None:
    home = tmp_path / "home"
    assert run_exe(home, "init").returncode == 0
    holder = sqlite3.connect(home / "catalog.sqlite", isolation_level=None, check_same_thread=False)
    holder.execute("BEGIN IMMEDIATE")  # a writer (a publish, say) holds the catalog
    released = threading.Event()

    def release_later() -> None:
        released.wait(20)
        holder.execute("ROLLBACK")

    threading.Thread(target=release_later, daemon=True).start()
    try:
        t0 = time.monotonic()
        args = ("site", "create", "a", "--crs", "EPSG:32610", "--origin", "493000", "4878000", "130")
        r = run_exe(home, *args, env={"SITELINE_CATALOG_WAIT_S": "1"})
        assert time.monotonic() - t0 < 15
    finally:
        released.set()
    assert r.returncode == 1, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) <= 3 and "Traceback" not in r.stderr, r.stderr
    assert "held by another writer" in r.stderr and "run it again" in r.stderr
    time.sleep(0.2)
    listed = run_exe(home, "site", "list")
    assert listed.returncode == 0 and " a " not in f" {listed.stdout} "  # nothing was stored
    assert run_exe(home, *args).returncode == 0  # and it goes through once the other writer is done
    r = run_exe(home, "site", "list", env={"SITELINE_CATALOG_WAIT_S": "soon"})
    assert r.returncode == 2 and "SITELINE_CATALOG_WAIT_S='soon'" in r.stderr, r.stderr
