"""Commands that would not fit in memory are refused before any work, with the figures (issue 53:
`calibrate` on a 60 s, 25.6 kHz record took more than 12 GB and was killed; "every command
estimates its memory before it starts and refuses, with the figure, what will not fit"). The
memory available is set by the test; the fits are replaced by stand-ins that fail the test if
they start."""

from __future__ import annotations

import numpy as np
import pytest
from _cli_errors import FITS, Started, one_error_line, stand_in_fits

from dtwin.cli import main
from dtwin.io.readers import write_record
from dtwin.io.record import Record
from dtwin.model.kinematics import Kinematics
from dtwin.simulation.memory import calibration_bytes, discovery_bytes, format_bytes
from dtwin.spec import preset

F_SUN = 29.7
GiB = 2**30


def _record(path, seconds: float, fs: float) -> str:
    """Paper-bench's gear lines at 29.7 Hz in noise."""
    kin = Kinematics.from_gear_set(preset("paper-bench").gear_set(), F_SUN)
    t = np.arange(int(round(seconds * fs))) / fs
    x = 0.05 * np.random.default_rng(0).standard_normal(t.size)
    for m in range(1, 4):
        for n in range(-2, 3):
            x += np.cos(2 * np.pi * (m * kin.f_mesh + n * kin.f_carrier) * t) / (m * (1 + abs(n)))
    write_record(Record(x[None, :], fs, ("acc",), ("m/s^2",), metadata={"f_sun": F_SUN}), path)
    return str(path)


@pytest.fixture()
def fits(monkeypatch):
    stand_in_fits(monkeypatch, FITS[2:])


def _available(monkeypatch, n_bytes: int) -> None:
    import dtwin.simulation.memory

    monkeypatch.setattr(dtwin.simulation.memory, "available_bytes", lambda: n_bytes)


def test_estimates_grow_with_the_record():
    small, big = calibration_bytes(20_000), calibration_bytes(60 * 25_600)
    assert 1.0 * GiB < small < 2.0 * GiB  # measured peak: 1.9 GB with the interpreter
    assert big > 12e9  # the record: killed beyond 12 GB
    assert discovery_bytes(60, 25_600, 22) > 20 * discovery_bytes(4, 5000, 22)


def test_calibrate_refuses_a_record_that_would_not_fit(tmp_path, fits, monkeypatch, capsys):
    rec = _record(tmp_path / "long.dtwin.h5", 20.0, 25_600.0)
    _available(monkeypatch, 4 * GiB)
    line = one_error_line(["calibrate", rec, "--preset", "paper-bench", "--out",
                           str(tmp_path / "out")], capsys)
    need = calibration_bytes(20 * 25_600)
    assert line.startswith(f"error: {rec}: calibrating on 20 s at 25600 Hz"), line
    assert f"needs about {format_bytes(need)} of memory, but 4 GiB is available" in line, line
    assert "shorter cut of the record" in line, line
    assert not (tmp_path / "out").exists()
    # a 4 s, 5 kHz record fits the same memory: the command goes on to its fit
    with pytest.raises(Started):
        main(["calibrate", _record(tmp_path / "short.dtwin.h5", 4.0, 5000.0), "--preset",
              "paper-bench", "--out", str(tmp_path / "out2")])


def test_discover_refuses_a_record_that_would_not_fit(tmp_path, fits, monkeypatch, capsys):
    rec = _record(tmp_path / "long.dtwin.h5", 20.0, 25_600.0)
    _available(monkeypatch, 1 * GiB)
    line = one_error_line(["discover", rec, "--preset", "paper-bench"], capsys)
    assert line.startswith(f"error: {rec}: discovering on 20 s at 25600 Hz"), line
    assert "of memory, but 1 GiB is available" in line, line
    with pytest.raises(Started):
        main(["discover", _record(tmp_path / "short.dtwin.h5", 4.0, 5000.0), "--preset",
              "paper-bench"])


def test_compare_drives_refuses_a_span_that_would_not_fit(monkeypatch, capsys):
    """`compare-drives --duration 3000`: XLA asked for 984 GB and the command ended in an
    internal error (exit 70); now one line with the estimate, before any simulation."""
    stand_in_fits(monkeypatch, (("dtwin.report.drive_comparison", "compare_drives"),))
    line = one_error_line(["compare-drives", "--preset", "paper-bench", "--duration", "3000"],
                          capsys)
    assert line.startswith("error: --duration: 5 severities × 3000.1 s at 5000 Hz"), line
    assert "TiB of memory, but" in line and "lower --duration" in line, line
    _available(monkeypatch, 4 * GiB)  # the default half second fits
    with pytest.raises(Started):
        main(["compare-drives", "--preset", "paper-bench"])
