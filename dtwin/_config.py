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
callback by default, which would keep every ODE solve and fit out of the cache. dtwin therefore
sets ``EQX_ON_ERROR=nan`` in the environment before equinox is imported (unless it is set
already: ``EQX_ON_ERROR=raise`` restores equinox's default): a failed check returns NaN, dtwin
runs its solvers with ``throw=False`` and reads their result codes, and the motor checks whose
message a user needs raise explicitly (``on_error="raise"``). The solves and fits then reach the
cache, and a second command reads them back instead of compiling them again. (A script that
imports equinox, diffrax or optimistix before dtwin keeps equinox's default.) It was opt-in for
a while: XLA once aborted a test process while writing a fit to the cache, the failure that
running out of memory mappings gives (:mod:`dtwin._maps`, which now keeps processes under the
limit).
"""

from __future__ import annotations

import os

os.environ.setdefault("EQX_ON_ERROR", "nan")  # before equinox is imported (module docstring)

import jax  # noqa: E402

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
