"""The documented error classes of dtwin.

Every error raised at a boundary (spec loading, record reading, CLI arguments, solver) is one
of these, with a message that says what was wrong and what to change. They subclass the
matching built-in (``ValueError``, ``RuntimeError``, ``OSError``) so generic handlers still work.
"""

from __future__ import annotations


class DtwinError(Exception):
    """Base class of all dtwin errors."""


def _is_command_line(path: str) -> bool:
    """Whether a problem's path names a command-line option (``--fault``, ``--preset/--spec``)
    or argument (``RESULTS``, ``FILE``) rather than a spec field (``gears.z_ring``)."""
    return path.startswith("-") or (path.replace("_", "").isalpha() and path.isupper())


class SpecError(DtwinError, ValueError):
    """A gearbox spec (TOML or dict) is invalid. ``problems`` lists (path, message) pairs.

    The message opens with "invalid spec:" unless every path names a command-line option or
    argument (a bad setting, not a bad spec): then it is ``OPTION: message``."""

    def __init__(self, problems: list[tuple[str, str]] | str):
        if isinstance(problems, str):
            problems = [("", problems)]
        self.problems = list(problems)
        lines = [f"{p}: {m}" if p else m for p, m in self.problems]
        head = ("invalid command line:" if all(_is_command_line(p) for p, _ in self.problems)
                else "invalid spec:")
        if len(lines) == 1 and head != "invalid spec:":
            super().__init__(lines[0])
        else:
            super().__init__(f"{head}\n  " + "\n  ".join(lines) if len(lines) > 1
                             else f"{head} " + lines[0])


class GeometryError(SpecError):
    """The gear geometry is impossible (teeth, planets that collide, ...)."""


class RecordError(DtwinError, ValueError):
    """A vibration record is unreadable or unusable (NaN, clipping, too short, wrong rate...)."""


class ChannelError(RecordError, KeyError):
    """A requested channel does not exist in a record."""

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0]) if self.args else ""


class UnreadableFileError(RecordError, OSError):
    """A file cannot be read: unknown format, truncated or corrupt."""


class OutputExistsError(DtwinError, FileExistsError):
    """An output would overwrite an existing result and overwriting was not requested."""


class SolverError(DtwinError, RuntimeError):
    """The ODE solver failed (max steps reached, NaN/inf in the state)."""


class FitError(DtwinError, RuntimeError):
    """A parameter fit failed to converge or hit a bound."""


class SettingsError(DtwinError, ValueError):
    """Settings of a fit, a discrepancy search or a fleet run are invalid (a value out of its
    allowed set or range, or settings that contradict each other)."""


class ParameterError(DtwinError, KeyError):
    """An unknown parameter name (not in :mod:`dtwin.model.registry`)."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""
