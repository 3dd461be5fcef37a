"""Ctrl-C while the ``dtwin`` command starts (importing JAX and the package takes seconds).

Imported first by ``dtwin/__init__.py``. When the process is the ``dtwin`` console script or
``python -m dtwin`` (and only then: a program that imports dtwin keeps its own SIGINT
handling), a SIGINT or SIGTERM before :func:`dtwin.cli.main` installs its handlers prints one
line and ends the process with 130 / 143, instead of a ``KeyboardInterrupt`` traceback from
deep inside an import. Nothing has been read or written by then.
"""

from __future__ import annotations

import os
import signal
import sys
import threading


def is_cli() -> bool:
    """Whether this process is the ``dtwin`` command (console script or ``python -m dtwin``)."""
    argv0 = sys.argv[0] if sys.argv else ""
    if os.path.basename(argv0) in ("dtwin", "dtwin.exe"):
        return True
    orig = getattr(sys, "orig_argv", [])
    return argv0 == "-m" and any(a == "dtwin" and i > 0 and orig[i - 1] == "-m"
                                 for i, a in enumerate(orig))


def _on_signal(signum: int, frame: object) -> None:
    name = "SIGTERM" if signum == signal.SIGTERM else "SIGINT"
    try:
        os.write(2, f"interrupted ({name}) while dtwin was starting: nothing was done\n".encode())
    finally:
        os._exit(128 + int(signum))


if is_cli() and threading.current_thread() is threading.main_thread():
    for _sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(_sig, _on_signal)
