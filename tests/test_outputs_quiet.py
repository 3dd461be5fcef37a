"""Quiet by default (issue #54): a cheap command on a bundled record writes nothing to stderr
but progress; warnings appear only where the user can act on them; third-party messages a user
cannot act on are silenced in the CLI, not in the library."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HEALTHY = ROOT / "data" / "samples" / "bench_healthy.dtwin.h5"


def test_spectrum_of_a_bundled_record_is_quiet_and_exports_what_its_report_shows(tmp_path):
    out, h5 = tmp_path / "spec", tmp_path / "export" / "spectrum.h5"
    env = dict(os.environ, MPLBACKEND="Agg")
    proc = subprocess.run(
        [sys.executable, "-m", "dtwin", "spectrum", str(HEALTHY), "--preset", "paper-bench",
         "--out", str(out), "--export", str(h5)],
        capture_output=True, text=True, env=env, timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    # nothing but progress: the written-files notes (no warning, no third-party line)
    noise = [ln for ln in proc.stderr.splitlines() if ln.strip() and not ln.startswith("wrote ")]
    assert not noise, proc.stderr
    # the HDF5 export holds the spectrum of the --out folder's CSV, to the last digit
    import h5py

    from dtwin.io.export import read_columns_csv

    cols, _ = read_columns_csv(out / "spectrum.csv")
    with h5py.File(h5) as f:
        assert np.array_equal(f["spectrum/frequency"][()], cols["frequency"])
        assert np.array_equal(f["spectrum/amplitude"][()], cols["amplitude"])
    # the report prints the peaks' frequencies to the hundredth (0.25 Hz bins: 510.75 Hz)
    page = (out / "report.html").read_text()
    peaks = [p for p in cols["frequency"] if abs(p - 510.75) < 1e-9]
    assert peaks and ">510.75<" in page and ">510.8<" not in page
    assert "Symbols of the line labels" in page  # fm, fc of the peak labels defined


def test_profile_shift_warns_only_when_dtwin_chose_the_centre_distance():
    from dtwin.model.gears import GearSet

    base = dict(z_sun=21, z_planet=31, z_ring=84, n_planets=3, module=0.002, face_width=0.02)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        GearSet(**base, centre_distance=0.0525)  # stated: nothing to act on
    assert not [x for x in w if "profile shift" in str(x.message)]
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        gs = GearSet(**base)  # chosen by dtwin: the message says how to state it
    msgs = [str(x.message) for x in w if "profile shift" in str(x.message)]
    assert len(msgs) == 1 and "gears.centre_distance" in msgs[0]
    assert float(gs.centre_distance) == 0.5 * (0.002 * 52 / 2 + 0.002 * 53 / 2)


def test_cli_silences_third_party_messages_and_keeps_dtwin_warnings():
    from dtwin.cli.logs import _THIRD_PARTY_LOGGERS, quiet_third_party

    ray_log = logging.getLogger(_THIRD_PARTY_LOGGERS[0])
    level = ray_log.level
    try:
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            quiet_third_party()
            warnings.warn("os.fork() was called. os.fork() is incompatible with multithreaded "
                          "code, and JAX is multithreaded, so this will likely lead to a "
                          "deadlock.", RuntimeWarning, stacklevel=1)
            warnings.warn("the record's speed disagrees with --f-sun", UserWarning,
                          stacklevel=1)
        assert [str(x.message) for x in w] == ["the record's speed disagrees with --f-sun"]
        assert not ray_log.isEnabledFor(logging.WARNING)
    finally:
        ray_log.setLevel(level)


def test_messages_name_values_without_python_reprs(capsys):
    """A wrong channel is named as the user typed it and the record's channels as a list of
    names, not as Python's list repr (``['vibration']``)."""
    import pytest

    from dtwin.cli import main

    with pytest.raises(SystemExit) as e:
        main(["spectrum", str(HEALTHY), "--channel", "9"])
    assert e.value.code == 2
    assert capsys.readouterr().err.strip() == (
        "error: --channel: unknown channel 9; the record has vibration (names or indices 0..0)")
