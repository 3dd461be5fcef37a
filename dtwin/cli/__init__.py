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


def _quiet_unraisable(default):
    """A ``sys.unraisablehook`` that drops a KeyboardInterrupt/Terminated the signal handler
    raised inside a finaliser or a garbage-collector callback (JAX registers one): Python
    cannot propagate it from there and would print "Exception ignored in …" with a traceback.
    The signal is already in :data:`_SIGNALS`; the command ends with the one ``interrupted``
    line (the watcher thread, or :func:`main` when the work returns). Anything else goes to
    `default`."""

    def hook(unraisable) -> None:
        if isinstance(unraisable.exc_value, (KeyboardInterrupt, Terminated)):
            return
        default(unraisable)

    return hook


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




def _is(e: object, name: str) -> bool:
    """Whether `e` is a click exception of class `name` (click's, or the copy typer vendors as
    ``typer._click``: compared by class name)."""
    return any(c.__name__ == name for c in type(e).__mro__)


def _words(tp: object) -> str:
    """A Python annotation in words: ``float`` → "a number", ``tuple[float, float]`` → "2
    numbers", ``Path | None`` → "a path"."""
    import pathlib
    import typing

    args = [a for a in typing.get_args(tp) if a is not type(None)]
    origin = typing.get_origin(tp)
    if origin in (tuple, list) and args:
        inner = _words(args[0]).replace("a ", "", 1).replace("an ", "", 1)
        if origin is list:
            return f"{_words(args[0])}, repeatable"
        return f"{len(args)} {inner}s"
    if args:  # Optional / Union
        return " or ".join(_words(a) for a in args)
    names = {int: "an integer", float: "a number", str: "text", bool: "a flag, no value"}
    if tp in names:
        return names[tp]
    if isinstance(tp, type) and issubclass(tp, pathlib.PurePath):
        return "a path"
    return "a value"


def _accepted(param: object) -> str:
    """What a command-line parameter accepts, in words (for the one-line usage error)."""
    if param is None:
        return "see --help"
    if getattr(param, "is_flag", False):
        return "a flag, no value"
    runtime = getattr(param, "get_runtime_param", None)
    try:
        annotation = runtime().annotation if callable(runtime) else None
    except Exception:
        annotation = None
    if annotation is not None:
        return _words(annotation)
    ptype = getattr(param, "type", None)  # plain click
    choices = getattr(ptype, "choices", None)
    if choices:
        return "one of " + ", ".join(str(c) for c in choices)
    return {"integer": "an integer", "float": "a number", "path": "a path"}.get(
        str(getattr(ptype, "name", "")), "a value")


def _options_of(ctx: object) -> list[str]:
    command = getattr(ctx, "command", None)
    names = [o for p in getattr(command, "params", []) for o in getattr(p, "opts", [])
             if o.startswith("--")]
    return names + ["--help"]


def _label(param: object, fallback: str) -> str:
    opts = list(getattr(param, "opts", None) or [])
    if not opts:
        return fallback
    if opts[0].startswith("-"):
        return max(opts, key=len)
    return str(getattr(param, "name", opts[0])).upper()


def _param_of(args: list[str] | None, option: str) -> object | None:
    """The parameter `option` of the command that `args` (the command line) names, or None; for
    the parser's errors, which carry no context."""
    if not args:
        return None
    import typer.main

    cmd = typer.main.get_command(app)
    for word in args:
        commands = getattr(cmd, "commands", None)
        if not commands:
            break
        if word in commands:
            cmd = commands[word]
        elif not word.startswith("-"):
            return None
    for p in getattr(cmd, "params", []):
        if option in (*getattr(p, "opts", ()), *getattr(p, "secondary_opts", ())):
            return p
    return None


def usage_error_line(e: Exception, args: list[str] | None = None) -> str:
    """A click usage error as one line ``error: <option>: <what> (accepted: <range>)``, the
    style of every other bad-input message of the CLI (click prints a usage block, typer with
    rich a box). `args`: the command line, which names the command of a parser error (an option
    without its value) that carries no context."""
    ctx = getattr(e, "ctx", None)
    names, c = [], ctx
    while c is not None and getattr(c, "parent", None) is not None:  # the root is the program
        names.insert(0, str(c.info_name))
        c = c.parent
    where = " ".join(["dtwin", *names])
    message = " ".join(str(getattr(e, "message", e)).split()).rstrip(".")
    if message.lower().startswith("value error, "):  # a parser's ValueError, through pydantic
        message = message[len("value error, "):]
    message = message[:1].lower() + message[1:]
    param = getattr(e, "param", None)
    if _is(e, "NoArgsIsHelpError") or message == "missing command":  # `dtwin`, `dtwin fleet`
        cmds = sorted(getattr(getattr(ctx, "command", None), "commands", None) or {})
        return (f"error: COMMAND: missing (accepted: {', '.join(cmds)}; see {where} --help)")
    if _is(e, "NoSuchOption"):
        close = list(getattr(e, "possibilities", None) or [])
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        return (f"error: {e.option_name}: no such option of {where} (accepted: "  # type: ignore[attr-defined]
                f"{', '.join(_options_of(ctx))}{hint})")
    if _is(e, "NoSuchCommand") or message.startswith("no such command"):
        cmds = sorted(getattr(getattr(ctx, "command", None), "commands", None) or {})
        name = message.split("'")[1] if "'" in message else message
        return (f"error: COMMAND: no such command {name!r} of {where} (accepted: "
                f"{', '.join(cmds)})")
    if _is(e, "MissingParameter"):
        accepted = _accepted(param)
        help_text = " ".join(str(getattr(param, "help", None) or "").split())
        if accepted == "text" and help_text:  # the help names what a text option takes
            accepted = help_text.split(". ")[0].rstrip(".")
            accepted = accepted[:1].lower() + accepted[1:]
        return (f"error: {_label(param, 'ARGUMENT')}: missing (accepted: {accepted}; "
                f"see {where} --help)")
    if _is(e, "BadParameter"):
        hint = str(getattr(e, "param_hint", None) or "value").strip("'\"")
        return f"error: {_label(param, hint)}: {message} (accepted: {_accepted(param)})"
    if _is(e, "BadOptionUsage"):  # raised by the parser, without a context
        import re

        name = getattr(e, "option_name", "option")
        message = re.sub(rf"^option '{re.escape(name)}' ", "", message)
        m = re.search(r"requires (\d+) arguments", message)
        param = _param_of(args, name) if ("requires" in message) else None
        accepted = (_accepted(param) if param is not None
                    else f"{m.group(1)} values" if m else "a value" if "requires an argument"
                    in message else "a flag, no value" if "does not take a value" in message
                    else "see --help")
        return f"error: {name}: {message} (accepted: {accepted})"
    return f"error: {where}: {message} (see {where} --help)"


#: Options that name a file or folder: an empty value would become the current folder.
PATH_OPTIONS = {"--out": "a folder (created if missing)", "--spec": "a spec file (TOML)",
                "--manifest": "a manifest.json file"}


def _empty_path_option(args: list[str]) -> str | None:
    """The one-line error for a path option given an empty value (``--out ''``), which the
    command line would read as the current folder; None when there is none."""
    for i, a in enumerate(args):
        name, eq, value = a.partition("=")
        if name in PATH_OPTIONS and ((eq and not value.strip()) or (
                not eq and i + 1 < len(args) and not args[i + 1].strip())):
            return f"error: {name}: is empty (accepted: {PATH_OPTIONS[name]})"
    return None


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
    empty = _empty_path_option(list(sys.argv[1:] if argv is None else argv))
    if empty:
        print(empty, file=sys.stderr)
        raise SystemExit(2)

    _SIGNALS.clear()
    old = {}
    old_unraisable = sys.unraisablehook
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            old[sig] = signal.signal(sig, _on_signal)
        sys.unraisablehook = _quiet_unraisable(old_unraisable)
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
    except Exception as e:  # usage errors (click's, bundled in typer): one `error:` line
        if isinstance(e.__cause__ or e.__context__, KeyboardInterrupt) or _SIGNALS:
            raise _interrupt_exit(_SIGNALS[0] if _SIGNALS else signal.SIGINT) from None
        if _is(e, "UsageError"):
            print(usage_error_line(e, list(sys.argv[1:] if argv is None else argv)),
                  file=sys.stderr)
            raise SystemExit(2) from None
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
        sys.unraisablehook = old_unraisable


__all__ = ["app", "main"]
