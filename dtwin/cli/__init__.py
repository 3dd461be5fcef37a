"""Command-line interface: ``dtwin COMMAND ...`` (see :mod:`dtwin.cli.app`)."""

from __future__ import annotations

import importlib
import os
import pkgutil
import signal
import sys
import threading

from .app import app


def _load_commands() -> None:
    for mod in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if mod.name.startswith("cmd_"):
            importlib.import_module(f"{__name__}.{mod.name}")


class Terminated(BaseException):
    """SIGTERM arrived (raised in the main thread by the handler :func:`main` installs)."""


_SIGNALS: list[int] = []


def _on_signal(signum: int, frame: object) -> None:
    _SIGNALS.append(signum)
    if signum == signal.SIGTERM:
        raise Terminated()
    raise KeyboardInterrupt()


def _interrupt_exit(signum: int) -> SystemExit:
    name = "SIGTERM" if signum == signal.SIGTERM else "SIGINT"
    print(f"interrupted ({name}): nothing was written to --out; run the same command again to "
          "start over (fleet runs resume)", file=sys.stderr)
    if _CONSOLE_SCRIPT:
        # The result folder is already clean (staged outputs were discarded on the way up).
        # Leave at once: a normal interpreter shutdown with XLA's threads still running a
        # host callback (progress, loss history) can crash (exit 139 instead of 130).
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(128 + int(signum))
    return SystemExit(128 + int(signum))


#: True while :func:`main` runs as the console script (no `argv` given), not in-process.
_CONSOLE_SCRIPT = False
#: Seconds the main thread gets to unwind after SIGINT/SIGTERM before the watcher ends the
#: process (a jitted fit or simulation does not return to Python until it has finished).
UNWIND_GRACE_S = 2.0


def _watch_signals() -> None:
    """A daemon thread woken by the C-level signal handler (``signal.set_wakeup_fd``): Python
    runs its own handlers only between bytecodes, so Ctrl-C during a long XLA computation would
    wait for its end. If the main thread has not left within :data:`UNWIND_GRACE_S`, the
    watcher removes unfinished staged results and exits with 130 / 143."""
    import time

    r, w = os.pipe()
    os.set_blocking(w, False)
    try:
        signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    except ValueError:  # not the main thread
        return

    def watch() -> None:
        while True:
            data = os.read(r, 16)
            sigs = [s for s in data if s in (signal.SIGINT, signal.SIGTERM)]
            if not sigs:
                continue
            time.sleep(UNWIND_GRACE_S)
            from ..io.output import discard_unfinished

            discard_unfinished()
            _interrupt_exit(sigs[0])  # prints the line and leaves (console script)

    threading.Thread(target=watch, name="dtwin-signals", daemon=True).start()




def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``dtwin`` console script.

    Exit codes: 0 done, 1 a fleet with failed records, 2 bad input (a
    :class:`~dtwin.errors.DtwinError` or a usage error, one ``error:`` line on stderr), 130
    interrupted by SIGINT (Ctrl-C), 143 terminated by SIGTERM, 70 an internal error (a bug:
    the traceback is shown with ``DTWIN_DEBUG=1``).
    """
    from ..errors import DtwinError
    from .logs import setup_logging

    global _CONSOLE_SCRIPT
    _CONSOLE_SCRIPT = argv is None
    if _CONSOLE_SCRIPT:  # one command, then the process ends: its caches need not outlive a fit
        from .. import _heap

        _heap.one_shot_process()
    setup_logging()
    _load_commands()

    _SIGNALS.clear()
    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            old[sig] = signal.signal(sig, _on_signal)
        if _CONSOLE_SCRIPT:
            _watch_signals()
    try:

        # typer turns Ctrl-C into `Exit(130)` and, outside standalone mode, *returns* the code
        rv = app(args=argv, standalone_mode=False)

    except DtwinError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    except (KeyboardInterrupt, Terminated):
        raise _interrupt_exit(_SIGNALS[0] if _SIGNALS else signal.SIGINT) from None
    except SystemExit:
        if _SIGNALS:
            raise _interrupt_exit(_SIGNALS[0]) from None
        raise
    except OSError as e:  # a file system refusal that no check foresaw: say what, no traceback
        print(f"error: {e}; check the path and its permissions", file=sys.stderr)
        raise SystemExit(2) from None
    except Exception as e:  # usage errors (click's, bundled in typer) print their message
        if isinstance(e.__cause__ or e.__context__, KeyboardInterrupt) or _SIGNALS:
            raise _interrupt_exit(_SIGNALS[0] if _SIGNALS else signal.SIGINT) from None
        show = getattr(e, "show", None)
        code = getattr(e, "exit_code", None)
        if callable(show) and isinstance(code, int):
            show()
            raise SystemExit(code) from None
        if type(e).__name__ == "Abort":
            raise SystemExit(1) from None
        if os.environ.get("DTWIN_DEBUG"):
            raise
        print(f"internal error: {type(e).__name__}: {e}\nthis is a bug in dtwin: please report "
              "it with the command line (DTWIN_DEBUG=1 shows the traceback)", file=sys.stderr)
        raise SystemExit(70) from None
    else:
        if _SIGNALS or rv == 130:  # an interrupt turned into a return code, or swallowed
            raise _interrupt_exit(_SIGNALS[0] if _SIGNALS else signal.SIGINT)
        if isinstance(rv, int) and rv != 0:
            raise SystemExit(rv)

    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)


__all__ = ["app", "main"]
