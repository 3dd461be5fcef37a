"""A process near the kernel's limit on memory mappings survives its compilations (dtwin._maps).

Every program XLA compiles for the CPU holds mappings of its own, and JAX keeps the programs of
a live function in its caches; a long process (a pytest-xdist worker of `make test`) reached
``vm.max_map_count`` and XLA's compiler killed it (`Fatal Python error: Segmentation fault` or
`Aborted` in ``backend_compile_and_load``; benchmarks/README.md, "XLA compiler crashes in
`make test`"). Here a child process fills its mapping table to a few hundred entries below the
limit, then compiles one program after another for one jitted function (as dtwin's solves
compile one per twin structure), passing a fit's safe point before each.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

linux = pytest.mark.skipif(not (os.path.exists("/proc/self/maps")
                                and os.path.exists("/proc/sys/vm/max_map_count")),
                           reason="needs /proc/self/maps and vm.max_map_count (Linux)")

CHILD = textwrap.dedent("""
    import ctypes, functools, sys
    import jax, jax.numpy as jnp
    from dtwin import _heap

    FREE, N = int(sys.argv[1]), int(sys.argv[2])
    libc = ctypes.CDLL("libc.so.6")
    libc.mmap.restype = ctypes.c_void_p
    libc.mmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int,
                          ctypes.c_int, ctypes.c_long]
    libc.mprotect.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]

    def count():
        with open("/proc/self/maps", "rb") as f:
            return f.read().count(b"\\n")

    @functools.partial(jax.jit, static_argnums=1)
    def f(x, k):  # ~26 mappings a program (kernels that do not fuse)
        y = jnp.cumsum(jnp.sort(jnp.sin(x) * k)) + jnp.cumsum(jnp.cos(x[::-1]) * k) @ jnp.ones((8, 8))
        return y + jnp.max(jnp.tanh(x) * k)
    f(jnp.ones(8), 0).block_until_ready()
    limit = int(open("/proc/sys/vm/max_map_count").read())
    # one anonymous block with every other page read-only: each mprotect adds two mappings
    n = max((limit - count() - FREE) // 2, 0)
    base = libc.mmap(None, (2 * n + 2) * 4096, 3, 0x22, -1, 0)  # RW, private anonymous
    for k in range(n):
        assert libc.mprotect(base + (2 * k + 1) * 4096, 4096, 1) == 0
    print("free", limit - count(), flush=True)
    for k in range(1, N + 1):
        _heap.before_first_fit()  # a fit's safe point
        f(jnp.ones(8), k).block_until_ready()  # a new program, kept in f's cache
    print("ok", flush=True)
""")


def _child(free: int, n: int, guard: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, DTWIN_MAP_GUARD=guard, DTWIN_JAX_CACHE="off", JAX_PLATFORMS="cpu")
    return subprocess.run([sys.executable, "-c", CHILD, str(free), str(n)], env=env,
                          capture_output=True, text=True, timeout=300)


FREE, N = 300, 24  # ~26 mappings a program: without the guard the table is full by the ~12th


@linux
def test_compilations_near_the_mapping_limit_do_not_kill_the_process():
    r = _child(FREE, N, "on")
    assert r.returncode == 0 and "ok" in r.stdout, (r.returncode, r.stdout, r.stderr[-2000:])


@linux
@pytest.mark.slow
def test_without_the_guard_the_same_compilations_kill_the_process():
    # what the test above guards against: XLA's compiler kills the child (a segfault or an
    # abort), or at least fails (should a later XLA report the full table as an error instead)
    r = _child(FREE, N, "off")
    assert r.returncode != 0 and "ok" not in r.stdout, (r.returncode, r.stdout)


def test_relieve_drops_the_caches_only_above_the_mark(monkeypatch):
    import jax
    import jax.numpy as jnp

    from dtwin import _maps

    monkeypatch.setattr(_maps, "map_limit", lambda: 1000)
    monkeypatch.setattr(_maps, "_mark", None)
    monkeypatch.setattr(_maps, "drops", 0)
    counts = iter([400, 900, 300])
    monkeypatch.setattr(_maps, "map_count", lambda: next(counts))
    f = jax.jit(lambda x: jnp.cos(x) + 2.0)
    f(jnp.ones(3)).block_until_ready()
    assert not _maps.relieve() and f._cache_size() == 1  # 400 of 1000: under the mark (500)
    monkeypatch.setattr(_maps, "_skip", 0)
    assert _maps.relieve() and f._cache_size() == 0  # 900: dropped, 300 after
    assert _maps.drops == 1 and _maps._mark == 650  # halfway from 300 to the limit
    monkeypatch.setenv("DTWIN_MAP_GUARD", "off")
    assert not _maps.relieve()


def test_relieve_does_nothing_inside_a_trace(monkeypatch):
    import jax
    import jax.numpy as jnp

    from dtwin import _maps

    monkeypatch.setattr(_maps, "map_limit", lambda: 1000)
    monkeypatch.setattr(_maps, "map_count", lambda: 999)
    monkeypatch.setattr(_maps, "_mark", None)
    seen = []
    jax.jit(lambda x: seen.append(_maps.relieve()) or x + 1)(jnp.ones(2))
    assert seen == [False]


def test_simulate_and_fits_pass_the_safe_point(monkeypatch):
    from dtwin import _heap, _maps
    from dtwin.simulation.simulate import simulate
    from dtwin.spec import preset
    from dtwin.spec.build import build_twin

    calls = []
    monkeypatch.setattr(_maps, "relieve", lambda: calls.append(1) or False)
    twin = build_twin(preset("paper-sim"), kind="torsional", f_sun=60.0)
    with pytest.raises(ValueError, match="duration"):
        simulate(twin, duration=-1.0, f_sun=60.0)
    assert calls == [1]
    _heap.before_first_fit()
    assert calls == [1, 1]
