"""`import dtwin` and `dtwin --help` stay light: the heavy optional libraries and the effect
library are imported by the functions that use them, not by the package or the CLI's start
(issue 51, item 7). The public names still import from the package."""

from __future__ import annotations

import inspect
import json
import subprocess
import sys

import pytest

#: Imported only when a command or function needs them (seconds each on two cores).
HEAVY = ("scipy.signal", "matplotlib", "ray", "pyarrow", "pandas", "dtwin.identify.discover.effects")

_REPORT = """
import json, sys
print(json.dumps(sorted(m for m in {heavy!r} if m in sys.modules)))
"""

_IMPORT = "import dtwin\n" + _REPORT

_HELP = """
import contextlib, io
from dtwin.cli import main

for argv in {argvs!r}:
    with contextlib.redirect_stdout(io.StringIO()) as out:
        try:
            main(argv)
        except SystemExit as e:
            assert e.code in (0, None), (argv, e.code)
    assert "Usage" in out.getvalue(), (argv, out.getvalue()[:500])
""" + _REPORT


def _heavy_after(code: str) -> list[str]:
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_import_dtwin_leaves_heavy_libraries_unimported():
    assert _heavy_after(_IMPORT.format(heavy=HEAVY)) == []


def test_cli_help_leaves_heavy_libraries_unimported():
    """``dtwin --help`` and the help of the long-running commands import every command module
    (:func:`dtwin.cli._load_commands`) but none of the libraries their work needs."""
    argvs = [["--help"], ["calibrate", "--help"], ["discover", "--help"],
             ["fleet", "--help"], ["identify", "--help"]]
    assert _heavy_after(_HELP.format(argvs=argvs, heavy=HEAVY)) == []


def test_a_deferred_library_is_imported_when_used():
    """The deferral is real, not a removal: the first spectrum's peak search imports
    scipy.signal and finds the line a sine puts there."""
    code = """
import numpy as np
import dtwin
fs, n = 1000.0, 1000
x = np.sin(2 * np.pi * 125.0 * np.arange(n) / fs)
freqs, spec = dtwin.amplitude_spectrum(x, fs, window="hann")
peaks = dtwin.find_peaks(freqs, spec, threshold_db=20.0)
print([round(float(p.frequency), 3) for p in peaks])
""" + _REPORT.format(heavy=HEAVY)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.strip().splitlines()
    assert lines[-2] == "[125.0]"
    assert json.loads(lines[-1]) == ["scipy.signal"]


@pytest.mark.parametrize("package", ["dtwin", "dtwin.identify"])
def test_every_public_name_imports_from_the_package(package):
    """``from PACKAGE import NAME`` works for every name of ``PACKAGE.__all__``, and
    ``__all__`` lists exactly the package's public re-exports (its public attributes that are
    not submodules)."""
    import importlib

    mod = importlib.import_module(package)
    for name in mod.__all__:
        exec(f"from {package} import {name}", {})
    public = {n for n, v in vars(mod).items()
              if not n.startswith("_") and not inspect.ismodule(v)}
    assert public == set(mod.__all__) - {"__version__"}
