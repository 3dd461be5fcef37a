"""A record that holds none of the spec's mesh lines is refused at once by calibrate and
discover (issue "Nothing lost, nothing hangs": both fitted for minutes before), with a message
that says what to check."""

from __future__ import annotations

import time

import numpy as np
import pytest

from dtwin.errors import RecordError
from dtwin.io.record import Record
from dtwin.spec import preset


def _tone(f=200.0, fs=5000.0, seconds=4.0):
    t = np.arange(int(fs * seconds)) / fs
    x = np.sin(2 * np.pi * f * t) + 0.01 * np.random.default_rng(0).standard_normal(t.size)
    return Record(x[None, :], fs, ("accel",), ("m/s^2",))


@pytest.mark.parametrize("command", ["calibrate", "discover"])
def test_a_pure_tone_is_refused_in_seconds(command):
    from dtwin.identify.calibrate import calibrate
    from dtwin.identify.discover import discover

    t0 = time.perf_counter()
    with pytest.raises(RecordError, match="no mesh harmonic stands above the noise"):
        if command == "calibrate":
            calibrate([_tone()], preset("paper-bench"))
        else:
            discover(_tone(), preset("paper-bench"))
    assert time.perf_counter() - t0 < 60.0


# --- the command line: one shared check before any fit ---------------------------------------

#: The commands that fit, with the arguments they need besides the record.
FITS = {"severity": [], "identify": ["--free", "sun_fault"], "calibrate": ["--out", "{out}"],
        "discover": []}


def _boom(*a, **k):
    raise AssertionError("the fit started on a record that holds no mesh line")


@pytest.fixture()
def no_fit(monkeypatch):
    """The fits fail the test if they start."""
    from importlib import import_module

    for module, name in (("dtwin.identify.fit", "fit"),
                         ("dtwin.identify.severity", "estimate_severity"),
                         ("dtwin.identify.discover", "discover"),
                         ("dtwin.identify.calibrate", "calibrate")):
        monkeypatch.setattr(import_module(module), name, _boom)


@pytest.mark.parametrize("source", ["metadata", "lines", "given"])
@pytest.mark.parametrize("command", sorted(FITS))
def test_the_fitting_commands_refuse_a_record_without_mesh_lines_at_once(
        command, source, tmp_path, no_fit, capsys):
    """A 200 Hz tone in noise checked against paper-bench (mesh at 499 Hz): refused in seconds
    with one line that says the record holds no line at the spec's mesh frequency and what to
    check, whether the speed came from the record's metadata (before: a warning, then a fit of
    minutes to "NOT DETERMINED"), from the lines' own estimate or from --f-sun."""
    from dtwin.cli import main
    from dtwin.io.readers import write_record

    rec = _tone()
    if source == "metadata":
        rec = Record(rec.data, rec.sample_rate, rec.channels, rec.units,
                     metadata={"f_sun": 29.7})
    path = tmp_path / "tone.dtwin.h5"
    write_record(rec, path)
    argv = [command, str(path), "--preset", "paper-bench",
            *[a.format(out=tmp_path / "out") for a in FITS[command]],
            *(["--f-sun", "29.7"] if source == "given" else [])]
    t0 = time.perf_counter()
    with pytest.raises(SystemExit) as e:
        main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    lines = [ln for ln in err.splitlines() if not ln.startswith("warning: sun_fault fitted")]
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}: the record holds no line "
                                                   "at the spec's mesh frequency"), err
    assert "tooth numbers" in lines[0] and "channel" in lines[0], err
    assert time.perf_counter() - t0 < 30.0
