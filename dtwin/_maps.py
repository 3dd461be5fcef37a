"""Keeping the process under the kernel's limit on memory mappings (``vm.max_map_count``).

Every program XLA compiles for the CPU is loaded as machine code in memory of its own: per
compiled kernel, a code, a read-only and a data mapping that the kernel cannot merge with their
neighbours; ~3 mappings for a small program, 663 for a simulation's initial state and 488 for
its solve (benchmarks/README.md, "XLA compiler crashes in `make test`"). JAX keeps every
compiled program in its in-memory caches while the function it was compiled for lives; dtwin's
solves and fits are module-level functions, so a process that simulates and fits many twin
structures (a test worker, a notebook, a long fleet or discovery run) only ever adds mappings.
Linux refuses a process more than ``vm.max_map_count`` of them (65 530 by default; ``mmap(2)``
and ``mprotect(2)`` fail with ENOMEM: the Linux man-pages, and the kernel's
Documentation/admin-guide/sysctl/vm.rst, "max_map_count"), and XLA's CPU compiler does not fail
cleanly then: LLVM's JIT linker reports "Cannot allocate memory" and either aborts
(``report_fatal_error`` in ``RuntimeDyldImpl::emitSection``, on a compiler thread) or the
error's C++ exception segfaults in the unwinder (``_Unwind_Find_FDE``) on its way to Python:
`Fatal Python error: Segmentation fault` or `Aborted` inside ``backend_compile_and_load``
(jax/jaxlib 0.10.2). The same LLVM error in long JAX processes: jax-ml/jax#11923 (where
clearing JAX's caches cured it; JAX bounds its caches by entries, not by size) and
pasteurlabs/mosaic#15.

:func:`relieve`, called at dtwin's safe points (the start of :func:`dtwin.simulation.simulate.simulate`,
of every fit, of each discovery candidate's refit, and before each test), drops JAX's in-memory
caches (``jax.clear_caches``) once the process holds more than :data:`FRACTION` of the limit:
the programs that no live object holds are freed with their mappings, and the next call compiles
anew what it needs (or reads it from the persistent compilation cache). It does nothing inside a
JAX trace (clearing caches the trace is using is not safe) nor outside the main thread (another
thread may be compiling). After a drop the mark is halfway from what is left to the limit (at
least :data:`FRACTION` of it), so that mappings held by something else do not make every call
drop the caches again. Reading ``/proc/self/maps`` takes ~1.5 ms per thousand mappings, so it is
read again only once enough programs have been loaded since the last reading (a
`jax.monitoring` listener counts them, :data:`PROGRAM_MAPS` each) to have reached the mark: a
loop over one compiled program never reads it. ``DTWIN_MAP_GUARD=off`` (or ``0``, ``none``,
``false``, ``no``) turns it off. Raising ``vm.max_map_count`` (as root: ``sysctl -w
vm.max_map_count=262144``) is the system-wide remedy. Without ``/proc`` (macOS, Windows) it does
nothing.
"""

from __future__ import annotations

import functools
import gc
import os
import threading

import jax

from ._config import OFF_VALUES

FRACTION = 0.5
"""Share of ``vm.max_map_count`` above which :func:`relieve` drops JAX's caches."""

PROGRAM_MAPS = 1000
"""A generous bound on the mappings one loaded program adds (measured: a simulation's initial
state 663, its solve 488, small programs 2-3)."""

_BACKEND_COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"  # compiled or read back
_MAPS = "/proc/self/maps"
_LIMIT = "/proc/sys/vm/max_map_count"
_mark: int | None = None  # the count above which relieve drops the caches (None: not yet set)
_loaded = 0  # programs loaded since the count was last read
_skip = 0  # programs that may be loaded before the count must be read again
drops = 0
"""How many times this process has dropped JAX's caches for its mappings."""


def _on_event(event: str, duration: float, **_) -> None:
    global _loaded
    if event == _BACKEND_COMPILE_EVENT:
        _loaded += 1


jax.monitoring.register_event_duration_secs_listener(_on_event)


def map_count() -> int | None:
    """The number of memory mappings this process holds (lines of ``/proc/self/maps``), or None
    where the file does not exist."""
    try:
        with open(_MAPS, "rb") as f:
            return sum(chunk.count(b"\n") for chunk in iter(lambda: f.read(1 << 20), b""))
    except OSError:
        return None


@functools.lru_cache(maxsize=1)
def map_limit() -> int | None:
    """The kernel's limit on a process's mappings (``vm.max_map_count``), or None where unknown."""
    try:
        with open(_LIMIT) as f:
            return int(f.read().strip())
    except (OSError, ValueError):
        return None


def enabled() -> bool:
    """Whether the environment leaves the guard on (``DTWIN_MAP_GUARD``, default on)."""

    return os.environ.get("DTWIN_MAP_GUARD", "on").strip().lower() not in OFF_VALUES


def _tracing() -> bool:
    try:
        from jax._src import core
    except ImportError:  # pragma: no cover — a JAX without it: assume a trace may be running
        return True
    clean = getattr(core, "trace_state_clean", None)
    return clean is None or not clean()


def relieve() -> bool:
    """At a safe point (no JAX trace running): drop JAX's in-memory caches when this process
    holds more than :data:`FRACTION` of ``vm.max_map_count`` mappings. Returns whether it did."""
    global _mark, _loaded, _skip, drops
    limit = map_limit()
    if limit is None or not enabled():
        return False
    if _mark is None:
        _mark = int(FRACTION * limit)
    elif _loaded < _skip:  # too few programs loaded since the last reading to reach the mark
        return False
    n = map_count()
    _loaded = 0
    if n is None:
        return False
    if n <= _mark or _tracing() or threading.current_thread() is not threading.main_thread():
        _skip = max(_mark - n, 0) // PROGRAM_MAPS
        return False
    jax.clear_caches()
    gc.collect()
    drops += 1
    after = map_count() or 0
    # mappings that the drop could not free (held by live objects or another library) must not
    # make every later call drop the caches again: the next mark is halfway to the limit
    _mark = max(int(FRACTION * limit), after + (limit - after) // 2)
    _skip = max(_mark - after, 0) // PROGRAM_MAPS
    return True
