"""The check of a fit's speed against the record's mesh lines (``dtwin.cli.options``) before
``severity``, ``identify``, ``calibrate`` and ``discover``: a run-up's tachometer speed varies
within the record, no mesh line stands at its mean, and the fit follows the tachometer, so the
check neither warns nor refuses; a steady record's tachometer is still checked."""

import dataclasses

import numpy as np
from _bench import SAMPLES

from dtwin import read_record
from dtwin.cli.options import _tacho_varies, check_speed_against_lines
from dtwin.spec import preset


def test_a_runup_tachometer_is_not_checked_against_the_mean_speeds_lines(caplog):
    """bench_runup (20 → 35 Hz, a 1-pulse tachometer on the sun): no warning (it said that
    the tachometer's 27.5 Hz put fm where the record shows no line)."""
    rec = read_record(SAMPLES / "bench_runup.dtwin.h5")
    assert _tacho_varies(rec)
    op = check_speed_against_lines(rec, preset("paper-bench"), None, 0, "bench_runup")
    assert op is not None and op.method == "tacho" and 26.0 < op.f_sun < 29.0
    assert not [r for r in caplog.records if r.levelname == "WARNING"], caplog.text


def test_a_steady_tachometer_is_still_checked(caplog):
    """A steady 30 Hz tachometer on bench_healthy (29.7 Hz): the lines contradict it, and the
    check says so."""
    rec = read_record(SAMPLES / "bench_healthy.dtwin.h5")
    fs = rec.sample_rate
    t = np.arange(rec.channel(0).size) / fs
    pulses = (np.sin(2 * np.pi * 30.0 * t) > 0.99).astype(float)
    rec = dataclasses.replace(rec, tacho=pulses, tacho_ppr=1, tacho_shaft="sun")
    assert not _tacho_varies(rec)
    check_speed_against_lines(rec, preset("paper-bench"), None, 0, "healthy")
    assert "the tachometer's speed 29.99" in caplog.text and "disagrees" in caplog.text
