"""How many threads torch's CPU operators use while a pair renders: as many cores as the machine leaves
free at the time, never more than the process was given (OMP_NUM_THREADS, ``torch.set_num_threads``).

A pool of T threads meets at the end of every operator; on a machine whose other processes keep the
cores busy each meeting waits for the thread the scheduler left out, so many small operators (a pair's
probes and renders) run several times slower than the load explains. With one thread a loaded machine
costs what its load explains (bench/load.py, docs/performance.md)."""

from __future__ import annotations

import os
import statistics
import time

import torch

LOADAVG = "/proc/loadavg"
# how often the choice is made again (seconds): a build outlasts changes in the machine's load
EVERY_S = 2.0


def _own_running(tasks: str = "/proc/self/task") -> int:
    """This process's threads runnable now (the looking one included; a pool spinning between
    operators counts too)."""
    n = 0
    for t in os.listdir(tasks):
        try:
            with open(f"{tasks}/{t}/stat") as fh:
                n += fh.read().rsplit(")", 1)[1].split()[0] == "R"
        except (OSError, IndexError):
            continue
    return max(n, 1)


def runnable_others(samples: int = 3, pause_s: float = 0.003, path: str = LOADAVG) -> int | None:
    """Tasks of other processes runnable now (the median of ``samples`` looks at the kernel's run
    queue, less this process's runnable threads); None where the system does not say (not Linux)."""
    seen = []
    for k in range(samples):
        try:
            with open(path) as fh:
                running = int(fh.read().split()[3].split("/")[0])
            seen.append(running - _own_running())
        except (OSError, IndexError, ValueError):
            return None
        if k + 1 < samples:
            time.sleep(pause_s)
    return max(0, int(statistics.median(seen)))


def threads_for(cap: int, cores: int, others: int | None) -> int:
    """Threads for torch given at most ``cap``, the machine's ``cores`` and ``others`` runnable tasks
    of other processes (None: unknown, ``cap``): the cores they leave free, at least one."""
    if others is None:
        return max(1, cap)
    return max(1, min(cap, cores - others))


class CpuThreads:
    """Sets torch's thread count for the load of the moment when called, at most every ``every_s``
    seconds (a call in between costs a clock read); nothing on another device."""

    def __init__(self, device: str = "cpu", every_s: float = EVERY_S) -> None:
        self.active = device == "cpu"
        self.cap = torch.get_num_threads()
        self.cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        self.every_s = every_s
        self._last = -float("inf")
        self.chosen: list[int] = []

    def __call__(self) -> None:
        if not self.active or self.cap <= 1:
            return
        now = time.monotonic()
        if now - self._last < self.every_s:
            return
        self._last = now
        n = threads_for(self.cap, self.cores, runnable_others())
        if n != torch.get_num_threads():
            torch.set_num_threads(n)
        self.chosen.append(n)

    def restore(self) -> None:
        """Give torch back the thread count it had."""
        if self.active and torch.get_num_threads() != self.cap:
            torch.set_num_threads(self.cap)
