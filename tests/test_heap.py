"""The heap trim after compilations and the one-shot cache drop (dtwin._heap)."""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

import jax
import jax.numpy as jnp
import pytest

from dtwin import _heap

linux_glibc = pytest.mark.skipif(
    not sys.platform.startswith("linux") or _heap._TRIM is None,
    reason="malloc_trim is a glibc call")


def _rss_mib() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


@linux_glibc
def test_release_returns_freed_heap_pages_from_the_middle_of_the_heap():
    # 64 MiB in 1 KiB blocks, then one block kept above them: glibc's own trim on free only
    # shrinks the heap's top, so without malloc_trim the freed 64 MiB stay in the process.
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    blocks = [libc.malloc(1024) for _ in range(65536)]
    for b in blocks:
        ctypes.memset(b, 1, 1024)  # touch the pages
    keep = libc.malloc(1024)
    for b in blocks:
        libc.free(b)
    before = _rss_mib()
    assert _heap.release()
    after = _rss_mib()
    libc.free(keep)
    assert before - after > 32, (before, after)


@linux_glibc
def test_a_one_shot_process_installs_the_listener_once(monkeypatch):
    """The console script's process trims after long compilations; a library user's process
    (this one) does not, until it declares itself one-shot."""
    registered = []
    monkeypatch.setattr(jax.monitoring, "register_event_duration_secs_listener",
                        registered.append)
    monkeypatch.setattr(_heap, "_installed", False)
    monkeypatch.setattr(_heap, "_one_shot", False)
    monkeypatch.delenv("DTWIN_MALLOC_TRIM", raising=False)
    _heap.one_shot_process()
    _heap.one_shot_process()
    assert registered == [_heap._after_compile]
    monkeypatch.setattr(_heap, "_installed", False)
    monkeypatch.setenv("DTWIN_MALLOC_TRIM", "off")
    _heap.one_shot_process()  # switched off: nothing more registered
    assert registered == [_heap._after_compile]


def test_trim_switch_reads_the_environment(monkeypatch):
    for off in ("off", "0", "NO", " false "):
        monkeypatch.setenv("DTWIN_MALLOC_TRIM", off)
        assert not _heap.enabled()
    monkeypatch.setenv("DTWIN_MALLOC_TRIM", "on")
    assert _heap.enabled()


def test_caches_are_dropped_only_in_a_one_shot_process_and_only_once(monkeypatch):
    monkeypatch.setattr(_heap, "_one_shot", False)
    monkeypatch.setattr(_heap, "_cleared", False)
    monkeypatch.setattr(_heap, "install", lambda: True)  # no listener left in this process
    monkeypatch.setenv("DTWIN_MAP_GUARD", "off")  # no drop for the mapping limit (dtwin._maps)
    f = jax.jit(lambda x: jnp.sin(x) + 1.0)
    f(jnp.ones(3)).block_until_ready()
    assert f._cache_size() == 1
    assert not _heap.before_first_fit()  # a notebook or a script: its caches stay
    assert f._cache_size() == 1

    _heap.one_shot_process()
    assert _heap.before_first_fit()
    assert f._cache_size() == 0  # dropped: the next call compiles again
    f(jnp.ones(3)).block_until_ready()
    assert not _heap.before_first_fit()  # the second fit keeps what the first compiled
    assert f._cache_size() == 1
