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
