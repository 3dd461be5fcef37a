"""The one ``error:`` line of a command refused on bad input (exit 2), shared by the CLI's
reliability tests."""

from __future__ import annotations

import pytest

from dtwin.cli import main


def one_error_line(argv, capsys) -> str:
    """Run ``dtwin ARGV``; check it exits 2 with one ``error:`` line on stderr and return it."""
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]
