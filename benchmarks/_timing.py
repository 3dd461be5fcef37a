"""Shared timing helpers of the benchmark scripts (imported as ``_timing``: each script runs with
this folder first on ``sys.path``; ``run_all.py`` runs only ``bench_*.py``)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def load_average() -> tuple[float, float, float]:
    """The machine's 1, 5 and 15 minute load averages (the shared 2-core box's load is part of
    every timing: report it beside the figures)."""
    return os.getloadavg()


def timed(fn: Callable[[], T]) -> tuple[T, float, float]:
    """Call `fn()`; return its result, the wall time (s) and this process's CPU time (s)."""
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def wait_measured(proc, t0: float, timeout: float) -> dict:
    """Wait for the child process `proc` (a `subprocess.Popen` started at ``time.perf_counter()``
    = `t0`), killing it after `timeout` s: exit code, wall time (s), CPU time (user + system of
    the child and the processes it waited for, s), peak resident memory (MB) and whether it
    timed out (`os.wait4`'s resource usage)."""
    deadline = t0 + timeout
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        if time.perf_counter() > deadline:
            proc.kill()
            pid, status, usage = os.wait4(proc.pid, 0)
            break
        time.sleep(0.05)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    return {"returncode": proc.returncode, "wall_s": wall,
            "cpu_s": usage.ru_utime + usage.ru_stime, "peak_rss_mb": usage.ru_maxrss / 1024.0,
            "timed_out": wall > timeout}
