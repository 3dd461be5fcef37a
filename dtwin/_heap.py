"""Giving the heap that XLA's compiler leaves behind back to the operating system.

Compiling one of dtwin's fits (an ODE solve and its tangents, `jax.jit` through XLA and LLVM)
allocates some 500 MB of small, short-lived objects on the C heap. glibc's ``malloc`` keeps
the freed pages inside the process, so after the compilation the process stays that much
larger and every later allocation (the run of the compiled program, the next compilation)
stacks on top of it. ``malloc_trim(0)`` hands them back (since glibc 2.8 every whole free
page of every arena, not only the top of the heap: ``malloc_trim(3)``).

:func:`install` registers a `jax.monitoring` listener that trims after every compilation that
took longer than :data:`MIN_COMPILE_S` (the small programs of eager operations are left
alone). The ``dtwin`` console script, a process that runs one command and exits, declares
itself with :func:`one_shot_process`, which installs it unless ``DTWIN_MALLOC_TRIM=off`` (or
``0``, ``none``, ``false``, ``no``). A library user's process (a notebook, a script, the tests)
is left alone: there the heap that a trim gives back is soon needed again by the next
compilation, and growing it anew costs time (a few per cent of a calibration or a discovery;
benchmarks/README.md, "Big records"). Where the C library has no ``malloc_trim`` (macOS, Windows, musl)
:func:`release` does nothing.

A one-shot process also drops JAX's in-memory caches once, before its first fit's
compilation (:func:`before_first_fit`). Each program XLA compiled and JAX keeps holds
~1.5 MB of heap, and building a twin runs some fifty single operations eagerly (each a compiled
program of its own): ~70 MB that the fit's compilation would otherwise stack on.

Reference: the Linux man-pages project, ``malloc_trim(3)``; the GNU C Library manual, "Memory
Allocation Tunables".
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os

import jax

from . import _maps
from ._config import OFF_VALUES

MIN_COMPILE_S = 0.5
"""Compilations shorter than this (s) are not followed by a trim."""

_COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"


def _malloc_trim():
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


_TRIM = _malloc_trim()
_installed = False
_one_shot = False
_cleared = False


def release() -> bool:
    """Return the C heap's free pages to the operating system (``malloc_trim(0)``).

    Returns whether anything was released (``False`` also where the C library lacks the call).
    """
    if _TRIM is None:
        return False
    return bool(_TRIM(0))


def _after_compile(event: str, duration: float, **_) -> None:
    if event == _COMPILE_EVENT and duration >= MIN_COMPILE_S:
        release()


def enabled() -> bool:
    """Whether the environment leaves the trim on (``DTWIN_MALLOC_TRIM``, default on)."""

    return os.environ.get("DTWIN_MALLOC_TRIM", "on").strip().lower() not in OFF_VALUES


def install() -> bool:
    """Trim the heap after every compilation of at least :data:`MIN_COMPILE_S` seconds.

    Idempotent; returns whether the listener is in place (``False`` where the C library has
    no ``malloc_trim``).
    """
    global _installed
    if _TRIM is None:
        return False
    if not _installed:
        jax.monitoring.register_event_duration_secs_listener(_after_compile)
        _installed = True
    return True


def one_shot_process() -> None:
    """Declare that this process runs one command and exits (the ``dtwin`` console script):
    the heap is trimmed after long compilations (:func:`install`, unless
    ``DTWIN_MALLOC_TRIM=off``) and :func:`before_first_fit` drops JAX's caches."""
    global _one_shot
    _one_shot = True
    if enabled():
        install()


def before_first_fit() -> bool:
    """Called before a fit compiles: in a one-shot process, the first time only, drop JAX's
    in-memory caches (``jax.clear_caches``) and give the freed heap back (:func:`release`).

    Only once, so that a later fit in the same process (fleet, discovery) finds the programs
    that the first one compiled. Returns whether the caches were dropped.

    In every process, it is also a safe point of :func:`dtwin._maps.relieve`, which drops the
    caches when the process nears the kernel's limit on memory mappings.
    """
    global _cleared
    dropped = _maps.relieve()
    if not _one_shot or _cleared:
        return dropped
    _cleared = True
    jax.clear_caches()
    gc.collect()
    release()
    return True
