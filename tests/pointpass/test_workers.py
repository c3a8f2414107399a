"""The engine's worker pools: started once per process with the kernels loaded, spawned with one
allocator arena, a dead worker one clear error, and workers that exit when their parent dies."""

from __future__ import annotations

import os

import pytest


def test_started_workers_load_the_kernels_as_they_start() -> None:
    """The pool's workers import numba and load a kernel in their initializer, before any task."""
    from siteline.pointpass import process_pool, start_pool

    start_pool(2)
    pool = process_pool(2)
    loaded = [pool.submit(eval, "'numba' in __import__('sys').modules") for _ in range(4)]
    assert all(f.result(timeout=120) for f in loaded)


def test_workers_start_with_one_allocator_arena_and_leave_the_environment_alone(monkeypatch) -> None:
    """Workers spawn with MALLOC_ARENA_MAX=1 (their threads' memory stays on the one heap that keeps
    freed pages); this process's environment is as it was, and a value the user set wins."""
    import os

    from siteline.pointpass import workers

    monkeypatch.delenv("MALLOC_ARENA_MAX", raising=False)
    workers.discard_pool(3)
    try:
        pool = workers.process_pool(3)
        seen = {pool.submit(_worker_env_var).result(timeout=120) for _ in range(6)}
        assert seen == {"1"} and len(pool._processes) == 3  # all three spawned with it
        assert "MALLOC_ARENA_MAX" not in os.environ
        workers.discard_pool(3)
        monkeypatch.setenv("MALLOC_ARENA_MAX", "4")
        assert workers.process_pool(3).submit(_worker_env_var).result(timeout=120) == "4"
        assert os.environ["MALLOC_ARENA_MAX"] == "4"
    finally:
        workers.discard_pool(3)


def _worker_env_var() -> str | None:
    import os

    return os.environ.get("MALLOC_ARENA_MAX")


def _die(k: int) -> int:
    import os

    if k == 1:
        os._exit(9)  # a worker killed under the pass
    return k


def test_a_dead_worker_is_one_clear_error_and_the_next_pass_gets_a_fresh_pool(capsys, monkeypatch) -> None:
    from siteline import cli
    from siteline.errors import WorkerError
    from siteline.pointpass import pool_map, process_pool

    with pytest.raises(WorkerError, match="worker process died.*run the command again"):
        list(pool_map(process_pool(2), _die, range(4)))
    assert list(pool_map(process_pool(2), _die, [0, 2, 3])) == [0, 2, 3]

    def broken(*a, **k):  # noqa: ANN002, ANN003, ANN202
        raise WorkerError("a worker process died (killed, or out of memory)")

    monkeypatch.setattr(cli, "app", broken)
    assert cli.main(["ingest", "x", "--site", "s"]) == 1
    err = capsys.readouterr().err
    assert "worker process died" in err and "Traceback" not in err


KILLED_PARENT = """
import sys, time
from siteline.pointpass import process_pool
pool = process_pool(2)
pids = [pool.submit(__import__("os").getpid).result() for _ in range(4)]
print(" ".join(map(str, sorted(set(pids)))), flush=True)
time.sleep(60)
"""


def test_workers_of_a_killed_parent_exit_within_seconds() -> None:
    """kill -9 of a process holding the pool (an ingest killed mid-partition): its spawned workers,
    re-parented to init, notice within about a second and exit instead of holding their memory."""
    import os
    import signal
    import subprocess
    import sys
    import time

    proc = subprocess.Popen([sys.executable, "-c", KILLED_PARENT], stdout=subprocess.PIPE, text=True)
    try:
        workers = [int(p) for p in proc.stdout.readline().split()]
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert workers

    def alive(pid: int) -> bool:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return True

    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and any(alive(p) for p in workers):
        time.sleep(0.2)
    assert not any(alive(p) for p in workers)


SLOW_START = """
import os, time
if os.environ.get("SITELINE_TEST_SLOW_WORKER_START"):
    time.sleep(4)  # a worker still importing (12-30 s on a loaded machine) when its parent dies
"""
PARENT_OF_SLOW_WORKERS = """
import os, time
os.environ["SITELINE_TEST_SLOW_WORKER_START"] = "1"  # for the workers only: this process has started
from siteline.pointpass import process_pool
process_pool(2)
print(os.getpid(), flush=True)
time.sleep(60)
"""


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                status = open(f"/proc/{entry}/status").read()  # noqa: SIM115
            except OSError:
                continue
            if f"\nPPid:\t{pid}\n" in status:
                out.append(int(entry))
    return out


def test_workers_whose_parent_dies_before_they_start_exit_too(tmp_path) -> None:
    """kill -9 of an ingest while its pool workers are still importing: each worker takes the pid of
    the process that spawned it as an argument, so once it starts it sees that parent gone (a
    worker that read its parent's pid itself would read init's, and live on with the resource
    tracker). Both are gone within seconds."""
    import signal
    import subprocess
    import sys
    import time

    (tmp_path / "sitecustomize.py").write_text(SLOW_START)
    env = os.environ | {"PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen(
        [sys.executable, "-c", PARENT_OF_SLOW_WORKERS], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        parent = int(proc.stdout.readline())
        deadline = time.monotonic() + 10.0
        while (
            len(_children(parent)) < 3 and time.monotonic() < deadline
        ):  # two workers and the resource tracker
            time.sleep(0.1)
        children = _children(parent)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert len(children) >= 2

    def alive(pid: int) -> bool:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return open(f"/proc/{pid}/status").read().find("State:\tZ") < 0

    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and any(alive(p) for p in children):
        time.sleep(0.2)
    assert not any(alive(p) for p in children), [p for p in children if alive(p)]
