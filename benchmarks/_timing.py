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
