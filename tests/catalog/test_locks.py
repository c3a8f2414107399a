"""The SQLite catalog's named locks (flock on a file beside the database): one holder at a time across
processes, a killed holder's lock freed by the kernel, and no lock file left once its holder is done."""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import time
from pathlib import Path

import pytest

from siteline.catalog.engine import make_engine
from siteline.catalog.locks import exclusive, lock_file
from siteline.errors import CatalogError


def _count(db: str, counter: str, times: int) -> None:
    engine = make_engine(f"sqlite:///{db}")
    for _ in range(times):
        with exclusive(engine, "counter"):
            n = int(Path(counter).read_text())
            time.sleep(0.002)  # a lost update shows unless the lock holds
            Path(counter).write_text(str(n + 1))


def _hold(db: str, ready: str) -> None:
    with exclusive(make_engine(f"sqlite:///{db}"), "held"):
        Path(ready).touch()
        time.sleep(60)


def test_one_holder_at_a_time_and_no_file_left(tmp_path) -> None:
    db, counter = str(tmp_path / "catalog.sqlite"), tmp_path / "n"
    counter.write_text("0")
    ctx = mp.get_context("spawn")
    procs = [ctx.Process(target=_count, args=(db, str(counter), 25)) for _ in range(4)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    assert [p.exitcode for p in procs] == [0, 0, 0, 0]
    assert counter.read_text() == "100"
    assert not lock_file(db, "counter").exists() and not lock_file(db, "counter").parent.exists()


def test_a_killed_holder_frees_the_lock(tmp_path) -> None:
    db, ready = str(tmp_path / "catalog.sqlite"), tmp_path / "ready"
    holder = mp.get_context("spawn").Process(target=_hold, args=(db, str(ready)))
    holder.start()
    while not ready.exists():
        time.sleep(0.05)
    engine = make_engine(f"sqlite:///{db}")
    with (
        pytest.raises(CatalogError, match="held by another writer"),
        exclusive(engine, "held", timeout_s=0.5),
    ):
        pass
    os.kill(holder.pid, signal.SIGKILL)
    holder.join(10)
    with exclusive(engine, "held", timeout_s=5):
        assert lock_file(db, "held").exists()
    assert not lock_file(db, "held").exists()


def test_a_folder_pruned_while_made_is_made_again(tmp_path, monkeypatch) -> None:
    """mkdir(exist_ok=True) raises FileExistsError when another holder removes the lock folder between
    its mkdir and its is_dir check (seen once in CI with four processes): the lock is then taken anyway."""
    real_mkdir, raced = Path.mkdir, []

    def mkdir(self: Path, *args, **kwargs) -> None:
        if self.name.endswith(".locks") and not raced:
            raced.append(self)
            raise FileExistsError(17, "File exists", str(self))
        real_mkdir(self, *args, **kwargs)

    monkeypatch.setattr(Path, "mkdir", mkdir)
    db = str(tmp_path / "catalog.sqlite")
    with exclusive(make_engine(f"sqlite:///{db}"), "raced", timeout_s=5):
        assert lock_file(db, "raced").exists()
    assert raced


def test_a_file_where_the_lock_folder_goes_is_named(tmp_path) -> None:
    db = str(tmp_path / "catalog.sqlite")
    lock_file(db, "x").parent.write_text("not a folder")
    with (
        pytest.raises(CatalogError, match="lock folder but is a file"),
        exclusive(make_engine(f"sqlite:///{db}"), "x", timeout_s=1),
    ):
        pass
