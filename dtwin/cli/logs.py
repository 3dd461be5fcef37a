"""Messages of the CLI on stderr: warnings and notes through :mod:`logging`, one line each.

:func:`setup_logging` gives the ``dtwin`` logger one stderr handler that prints
``warning: MESSAGE`` (and notes as ``MESSAGE``), and routes Python warnings
(:func:`warnings.warn`, from the library) to it, so that a warning is one line without the
source file and line. ``dtwin --quiet`` (:func:`set_quiet`) keeps errors only.
"""

from __future__ import annotations

import logging
import sys
import warnings

LOGGER = logging.getLogger("dtwin")


class _Format(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        msg = " ".join(record.getMessage().split("\n"))
        if record.levelno >= logging.ERROR:
            return f"error: {msg}"
        if record.levelno >= logging.WARNING:
            return f"warning: {msg}"
        return msg


class _StderrHandler(logging.StreamHandler):
    """Writes to the current ``sys.stderr`` (test runners swap it)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    def emit(self, record: logging.LogRecord) -> None:
        self.stream = sys.stderr
        super().emit(record)


#: Warning texts shown in this command (one line each, whichever call site raised it again).
_SHOWN: set[str] = set()


def _showwarning(message, category, filename, lineno, file=None, line=None) -> None:
    text = str(message)
    if text in _SHOWN:
        return
    _SHOWN.add(text)
    LOGGER.warning("%s", text)


#: Messages of other packages that a dtwin user cannot act on, silenced in the CLI only (a
#: script or notebook sees them): JAX's warning that a multithreaded process forks (Ray starts
#: its workers by fork/exec, with nothing of JAX's state in the child), and Ray's note that a
#: local cluster has its token authentication on by default.
_THIRD_PARTY_WARNINGS = (
    (r"os\.fork\(\) was called", RuntimeWarning),
)
_THIRD_PARTY_LOGGERS = ("ray._private.authentication.authentication_token_setup",)


def quiet_third_party() -> None:
    """Silence the messages of :data:`_THIRD_PARTY_WARNINGS` and :data:`_THIRD_PARTY_LOGGERS`
    for this process (the ``dtwin`` command calls it at its start)."""
    for message, category in _THIRD_PARTY_WARNINGS:
        warnings.filterwarnings("ignore", message=message, category=category)
    for name in _THIRD_PARTY_LOGGERS:
        logging.getLogger(name).setLevel(logging.ERROR)


def setup_logging(quiet: bool = False) -> None:
    """One stderr handler on the ``dtwin`` logger; Python warnings go through it, each text
    once per command; other packages' messages a user cannot act on are silenced
    (:func:`quiet_third_party`)."""
    _SHOWN.clear()
    quiet_third_party()
    if not any(isinstance(h, _StderrHandler) for h in LOGGER.handlers):
        handler = _StderrHandler()
        handler.setFormatter(_Format())
        LOGGER.addHandler(handler)
        LOGGER.propagate = False
    set_quiet(quiet)
    warnings.showwarning = _showwarning


def set_quiet(quiet: bool) -> None:
    """``--quiet``: errors only (no warnings, notes or progress)."""
    LOGGER.setLevel(logging.ERROR if quiet else logging.INFO)


def is_quiet() -> bool:
    return LOGGER.level >= logging.ERROR


def note(message: str) -> None:
    """An informative line on stderr (silenced by ``--quiet``)."""
    LOGGER.info("%s", message)


def warn(message: str) -> None:
    """One ``warning:`` line on stderr (silenced by ``--quiet``)."""
    LOGGER.warning("%s", message)
