"""torch's CPU threads follow the machine's load (siteline.render.threads): the cores other runnable
tasks leave free, never more than the process was given, at least one; nothing on another device."""

from __future__ import annotations

import multiprocessing
import time
from pathlib import Path

import pytest
import torch

from siteline.render.threads import LOADAVG, CpuThreads, runnable_others, threads_for


@pytest.mark.parametrize(
    ("cap", "cores", "others", "want"),
    [(2, 2, 0, 2), (2, 2, 1, 1), (2, 2, 6, 1), (8, 16, 4, 8), (8, 16, 12, 4), (4, 4, None, 4), (1, 16, 0, 1)],
)
def test_threads_are_the_cores_the_others_leave(cap, cores, others, want) -> None:
    assert threads_for(cap, cores, others) == want


def test_the_run_queue_is_read_less_this_process(tmp_path) -> None:
    fake = tmp_path / "loadavg"
    fake.write_text("7.10 6.50 5.20 9/456 12345\n")
    assert runnable_others(samples=1, path=str(fake)) == 8  # 9 runnable, this process's 1 thread looking
    fake.write_text("garbage\n")
    assert runnable_others(samples=1, path=str(fake)) is None


def _spin(stop) -> None:  # noqa: ANN001
    while not stop.is_set():
        pass


def test_busy_processes_are_seen_and_the_count_is_given_back() -> None:
    before = torch.get_num_threads()
    stop = multiprocessing.Event()
    spinners = [multiprocessing.Process(target=_spin, args=(stop,), daemon=True) for _ in range(3)]
    for p in spinners:
        p.start()
    try:
        time.sleep(0.3)
        seen = runnable_others(samples=5)
        if not Path(LOADAVG).exists():
            assert seen is None  # not Linux: the system does not say
        else:
            assert (
                seen is not None and seen >= 2
            )  # the three spinners (one may be off the queue for an instant)
        governor = CpuThreads("cpu", every_s=0.0)
        governor.cap = 4  # as if the process had been given 4 threads
        governor.cores = 2
        governor()
        assert governor.chosen == [1] and torch.get_num_threads() == 1
    finally:
        stop.set()
        for p in spinners:
            p.join(5)
        governor.restore()
    assert torch.get_num_threads() == 4  # restore gives back the cap it started from
    torch.set_num_threads(before)
    idle = CpuThreads("cuda")
    idle()
    assert idle.chosen == [] and torch.get_num_threads() == before
