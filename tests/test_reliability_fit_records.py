"""Records a fit cannot use are refused before any fit, in seconds, with one ``error:`` line
that says what to change: a record too short for the carrier sidebands (the rule of
``dtwin.io.validate``: the thresholds follow from the spec's carrier frequency at the record's
speed), a rate below what the spec's mesh frequency needs, and a ``--f-sun`` the record's mesh
lines contradict (both speeds named). The fits themselves are replaced by functions that fail
the test if they start."""

from __future__ import annotations

import time

import numpy as np
import pytest
from _cli_errors import Started, one_error_line, stand_in_fits

from dtwin.cli import main
from dtwin.io.readers import write_record
from dtwin.io.record import Record
from dtwin.io.validate import MIN_CARRIER_PERIODS
from dtwin.model.kinematics import Kinematics
from dtwin.spec import preset

F_SUN = 29.7  # paper-bench's speed: fm = 498.96 Hz, fc = 5.94 Hz


def _kin(f_sun: float = F_SUN) -> Kinematics:
    return Kinematics.from_gear_set(preset("paper-bench").gear_set(), f_sun)


def _mesh_record(path, *, seconds: float = 4.0, fs: float = 5000.0, metadata=None):
    """Paper-bench's gear lines at 29.7 Hz (mesh harmonics 1-4 with carrier sidebands, those
    below 0.45 × the rate) in noise."""
    kin = _kin()
    t = np.arange(int(round(seconds * fs))) / fs
    x = 0.05 * np.random.default_rng(0).standard_normal(t.size)
    for m in range(1, 5):
        for n in range(-3, 4):
            f = m * kin.f_mesh + n * kin.f_carrier
            if f < 0.45 * fs:
                x += np.cos(2 * np.pi * f * t + m + n) / (m * (1 + abs(n)))
    write_record(Record(x[None, :], fs, ("acc",), ("m/s^2",), metadata=metadata or {}), path)
    return str(path)


@pytest.fixture()
def fits(monkeypatch):
    stand_in_fits(monkeypatch)


def _refused(argv, capsys) -> str:
    """The one ``error:`` line of a command refused before any fit (within seconds)."""
    t0 = time.perf_counter()
    line = one_error_line(argv, capsys)
    assert time.perf_counter() - t0 < 30.0
    return line


def test_severity_refuses_a_record_too_short_for_the_carrier_sidebands(tmp_path, fits, capsys):
    """0.25 s of paper-bench (carrier 5.94 Hz): under the fit's own 2 carrier periods
    (0.34 s), refused at once in one line naming the length to record, 8 carrier periods
    (MIN_CARRIER_PERIODS, derived from the spec's carrier frequency at the record's speed)."""
    rec = _mesh_record(tmp_path / "short.dtwin.h5", seconds=0.25, metadata={"f_sun": F_SUN})
    line = _refused(["severity", rec, "--preset", "paper-bench"], capsys)
    need = MIN_CARRIER_PERIODS / _kin().f_carrier
    assert "too short to resolve the carrier sidebands (5.94 Hz apart)" in line, line
    assert f"{MIN_CARRIER_PERIODS:g} carrier periods = {need:.4g} s" in line, line
    assert f"record at least {need:.4g} s" in line, line


def test_severity_warns_of_a_record_that_the_fit_can_still_resolve(tmp_path, fits, capsys):
    """1 s of paper-bench is 5.9 carrier periods: the fit's sidebands stand 5.9 bins apart
    (resolved; the estimate agrees with the 4 s record's), so the fit runs after a warning that
    names the 8 carrier periods calibration would need."""
    rec = _mesh_record(tmp_path / "one.dtwin.h5", seconds=1.0)
    with pytest.raises(Started):
        main(["severity", rec, "--preset", "paper-bench"])
    err = capsys.readouterr().err
    assert "warning: the record lasts 1 s, too short to resolve the carrier sidebands" in err


def test_calibrate_refuses_a_rate_below_what_the_mesh_needs(tmp_path, fits, capsys):
    """A 500 Hz record of paper-bench (mesh at 499 Hz) without --f-sun: the rate is checked at
    the spec's speed and refused at once, naming the rate needed (before: the library's "no
    mesh harmonic lies below 225 Hz" after the progress line, no rate named)."""
    rec = _mesh_record(tmp_path / "slow.dtwin.h5", fs=500.0)
    line = _refused(["calibrate", rec, "--preset", "paper-bench", "--out",
                     str(tmp_path / "out")], capsys)
    assert "sampling rate 500 Hz is too low for the mesh frequency 498.96 Hz" in line, line
    assert "record at ≥ 1248 Hz" in line, line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["severity", "calibrate", "discover"])
def test_a_speed_the_record_contradicts_is_refused_naming_both(command, tmp_path, fits, capsys):
    """`--f-sun 20` on a record whose lines say 29.7 Hz: refused before any fit (calibrate
    and discover fitted at 20 Hz for minutes before), naming the given speed and the lines'."""
    rec = _mesh_record(tmp_path / "bench.dtwin.h5")
    extra = ["--out", str(tmp_path / "out")] if command == "calibrate" else []
    line = _refused([command, rec, "--preset", "paper-bench", "--f-sun", "20", *extra], capsys)
    assert "--f-sun 20 Hz disagrees with the record's mesh lines" in line, line
    assert "put the input speed at 29.70" in line and "drop --f-sun" in line, line
