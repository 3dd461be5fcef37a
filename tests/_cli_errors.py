"""The one ``error:`` line of a command refused on bad input (exit 2), and stand-ins for the
fits that show a command got past its checks, shared by the CLI's reliability tests."""

from __future__ import annotations

import pytest

from dtwin.cli import main

#: The library entries the CLI's fitting commands call, as (module, name).
FITS = (("dtwin.identify.fit", "fit"),
        ("dtwin.identify.severity", "estimate_severity"),
        ("dtwin.identify.discover", "discover"),
        ("dtwin.identify.calibrate", "calibrate"))


class Started(Exception):
    """Raised by the stand-ins of the fits: the command got past its checks."""


def _started(*a, **k):
    raise Started


def stand_in_fits(monkeypatch, fits=FITS) -> None:
    """Replace `fits` by stand-ins that raise :class:`Started` (``DTWIN_DEBUG`` set, so that
    the exception reaches the test rather than the CLI's error handler)."""
    from importlib import import_module

    monkeypatch.setenv("DTWIN_DEBUG", "1")
    for module, name in fits:
        monkeypatch.setattr(import_module(module), name, _started)


def one_error_line(argv, capsys) -> str:
    """Run ``dtwin ARGV``; check it exits 2 with one ``error:`` line on stderr and return it."""
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]
