"""Process-wide JAX configuration: float64 and a persistent compilation cache.

Imported first by :mod:`dtwin`. float64 is required (docs/references.md §6: in float32 the adaptive
solver stalls on kHz mesh forcing). The compilation cache lives in the user's cache folder,
``$XDG_CACHE_HOME/dtwin/jax`` (``~/.cache/dtwin/jax`` when ``XDG_CACHE_HOME`` is unset), shared
by every dtwin command, script and virtual environment of that user, so a second command does
not compile again what the first compiled. ``DTWIN_JAX_CACHE`` names another folder; set
``DTWIN_JAX_CACHE=off`` (or ``0``, ``none``, ``false``, ``no``) to disable it and
``DTWIN_JAX_CACHE=on`` (or ``1``, ``true``, ``yes``) for the default folder. ``make test``
points it at ``.venv/jax-cache`` so that test runs leave the user's cache alone.

JAX never writes a program that calls back to the host to the persistent cache, and equinox's
run-time checks (``eqx.error_if``, inside diffrax, optimistix and lineax) raise through such a
callback by default, so the ODE solves and the fits are compiled anew in every process; only
small programs are read back. With ``EQX_ON_ERROR=nan`` set in the environment before equinox
is imported (a failed check returns NaN; dtwin runs those solvers with ``throw=False`` and
reads their result codes, and the motor checks whose message a user needs raise explicitly)
the solves and fits are cached too: a fit of a 60 s record then took 18 s instead of 27 s on
its next run, discovery 52 s instead of 61 s. dtwin does not set it for you: in one of two
full test runs with it, XLA aborted the process while serializing a fit for the cache
(``Fatal Python error: Aborted`` in ``executable.serialize()``, jax/jaxlib 0.10.2 on the
2-core CPU; not reproduced alone), and an abort cannot be caught. XLA's CPU compiler has since
killed test processes without it too (an abort and a segmentation fault inside
``backend_compile_and_load``), so the setting may not be the cause; it stays opt-in until that
is known.
"""

from __future__ import annotations

import os

import jax

jax.config.update("jax_enable_x64", True)


#: Values of a ``DTWIN_…`` switch (any case) that turn it off.
OFF_VALUES = ("off", "0", "none", "false", "no")


def default_cache_dir() -> str:
    """The user's cache folder for JAX's compiled programs: ``$XDG_CACHE_HOME/dtwin/jax``, or
    ``~/.cache/dtwin/jax`` when ``XDG_CACHE_HOME`` is unset or not an absolute path (the XDG
    base directory specification)."""
    base = os.environ.get("XDG_CACHE_HOME", "")
    if not os.path.isabs(base):
        base = os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "dtwin", "jax")


def cache_dir() -> str | None:
    """The folder ``DTWIN_JAX_CACHE`` asks for (None: no persistent cache)."""
    env = os.environ.get("DTWIN_JAX_CACHE")
    if env is None or env.lower() in ("on", "1", "true", "yes"):
        return default_cache_dir()
    if env.lower() in ("", *OFF_VALUES):
        return None
    return os.path.expanduser(env)


_dir = cache_dir()
if _dir is not None:
    try:
        os.makedirs(_dir, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", _dir)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    except (OSError, AttributeError):  # an unwritable folder or an older jax: no cache
        pass
