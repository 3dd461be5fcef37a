"""Fit windows (dtwin.identify.segment, issue #20 item 5): a long record is fitted on a steady
stretch at the rate the fit needs; records no longer than the window are fitted as they are."""

import numpy as np
import pytest
import scipy.signal

from dtwin import preset
from dtwin.errors import SettingsError
from dtwin.identify.segment import FitWindow, segment_for_fit
from dtwin.io import Record
from dtwin.io.readers import read_record
from dtwin.model.kinematics import Kinematics
from dtwin.simulation.simulate import daq_filter

FS = 25600.0
F_SUN = 29.7


@pytest.fixture(scope="module")
def spec():
    return preset("paper-bench")


def _run(duration: float, ramp_until: float, spec, *, tacho: bool, bins: bool = False):
    """A record whose input speed rises from 0.9 F_SUN to F_SUN over ``ramp_until`` s and stays
    there: mesh harmonics 1–4 with carrier sidebands (phase = mesh order × sun angle), noise,
    and, with `tacho`, one pulse per sun revolution. With `bins`, steady lines at whole
    multiples of 0.25 Hz instead (a 4 s window holds whole periods of them)."""
    kin = Kinematics.from_gear_set(spec.gear_set(), 1.0)
    mo, co = kin.f_mesh, kin.f_carrier
    n = int(duration * FS)
    t = np.arange(n) / FS
    f = np.where(t < ramp_until, F_SUN * (0.9 + 0.1 * t / ramp_until), F_SUN)
    ang = 2 * np.pi * np.cumsum(f) / FS  # sun angle (rad)
    rng = np.random.default_rng(0)
    x = 0.05 * rng.standard_normal(n)
    if bins:
        for h, f_line in enumerate((498.75, 997.5, 1496.25, 1995.0), start=1):
            x += np.cos(2 * np.pi * f_line * t + h) / h
    else:
        for h in range(1, 5):
            x += (1 + 0.3 * np.cos(3 * co * ang)) * np.cos(h * mo * ang) / h
    kw = {}
    if tacho:
        kw = {"tacho": (np.mod(ang, 2 * np.pi) < 0.3).astype(float) * 5.0, "tacho_ppr": 1,
              "tacho_shaft": "sun"}
    return Record(x[None, :], FS, ("acc",), ("m/s^2",), metadata={"f_sun": F_SUN}, **kw)


def test_a_record_no_longer_than_the_window_is_fitted_as_it_is(spec):
    rec = read_record("data/samples/bench_healthy.dtwin.h5")  # 4 s at 5 kHz
    seg = segment_for_fit(rec, spec)
    assert seg.record is rec and not seg.windowed
    assert seg.describe().startswith("fitted on the whole record (4.0 s")
    full = segment_for_fit(_run(12.0, 6.0, spec, tacho=False), spec, window="full")
    assert full.record.n_samples == int(12.0 * FS) and not full.windowed


@pytest.mark.parametrize("tacho", [True, False])
def test_the_steadiest_stretch_is_chosen(spec, tacho):
    """The speed ramps for 6 s, then holds: the window (max(4 s, 20 / 5.94 Hz) = 4 s) starts
    where the speed holds (the first whole steady second, 6 s)."""
    rec = _run(12.0, 6.0, spec, tacho=tacho)
    before = rec.data.copy()
    seg = segment_for_fit(rec, spec)
    assert seg.chosen == "steadiest" and seg.length == pytest.approx(4.0)
    assert 6.0 <= seg.start <= 6.0 + 1e-9
    assert seg.speed_spread < 1e-3
    np.testing.assert_array_equal(rec.data, before)  # the input is not modified
    # 4 harmonics and their ±4 N fc bands below 0.45 × rate at 1.1 × 29.7 Hz: 25600 / 5
    kin = Kinematics.from_gear_set(spec.gear_set(), 1.1 * F_SUN)
    assert 4 * kin.f_mesh + 4 * kin.f_planet_pass <= 0.45 * 5120.0
    assert 4 * kin.f_mesh + 4 * kin.f_planet_pass > 0.45 * FS / 6
    assert seg.sample_rate == 5120.0 and seg.record.sample_rate == 5120.0
    assert seg.record.n_samples == int(4.0 * 5120)
    if tacho:  # every pulse kept: one per revolution of the sun
        from dtwin.signal.order import tacho_times

        pulses = tacho_times(seg.record.tacho, seg.record.sample_rate)
        assert pulses.size == pytest.approx(4.0 * F_SUN, abs=1.5)
    assert seg.describe() == (f"fitted on 4.0 s of 12.0 s (from 6.0 s, the steadiest; input "
                              f"speed within {100 * seg.speed_spread:.2g} %), decimated to "
                              "5120 Hz")
    assert seg.record.metadata["fit_window"]["decimation"] == 5


def test_decimated_lines_are_the_full_rate_lines_through_the_daq_filter(spec):
    """On a given window, each line's amplitude at 5120 Hz equals its amplitude at 25.6 kHz
    (same 4 s, same Hann window) times the gain of dtwin.simulation.simulate.daq_filter(5) at that
    frequency (scipy.signal.freqz): the filter the twin's own DAQ applies."""
    rec = _run(12.0, 0.5, spec, tacho=False, bins=True)
    seg = segment_for_fit(rec, spec, window="6:4")
    assert seg.chosen == "given" and seg.decimation == 5
    x_full = rec.data[0, int(6 * FS): int(10 * FS)]
    x_dec = seg.record.data[0]

    def amp(x):
        w = scipy.signal.get_window("hann", x.size)
        return np.abs(np.fft.rfft((x - x.mean()) * w)) * 2 / w.sum()

    a_full, a_dec = amp(x_full), amp(x_dec)
    for f_line in (498.75, 997.5, 1496.25, 1995.0):
        k = int(round(f_line * 4.0))
        _, h = scipy.signal.freqz(daq_filter(5), worN=[f_line], fs=FS)
        assert a_dec[k] == pytest.approx(a_full[k] * abs(h[0]), rel=1e-3)


def test_window_text_and_bad_windows(spec):
    assert FitWindow.parse("auto") == FitWindow() and FitWindow.parse(None) == FitWindow()
    assert FitWindow.parse("full").whole
    assert FitWindow.parse("2.5:4") == FitWindow(2.5, 4.0)
    for bad in ("4", "a:b", "-1:4", "1:0", "1:nan", "inf:2"):
        with pytest.raises(SettingsError, match="fit window"):
            FitWindow.parse(bad)
    rec = _run(12.0, 6.0, spec, tacho=False)
    with pytest.raises(SettingsError, match="past the record's end"):
        segment_for_fit(rec, spec, window="10:4")
    with pytest.raises(SettingsError, match="carrier sidebands"):
        segment_for_fit(rec, spec, window="0:0.2")  # 2 / 5.94 Hz = 0.34 s needed


def test_identify_and_severity_fit_the_window(spec, tmp_path, monkeypatch, capsys):
    """The commands hand the fit the window (4 s at 5120 Hz of a 12 s, 25.6 kHz record)."""
    from dtwin.cli import main
    from dtwin.errors import FitError
    from dtwin.io.readers import write_record

    path = tmp_path / "long.dtwin.h5"
    write_record(_run(12.0, 6.0, spec, tacho=True), path)
    seen = []

    def fake(records, *a, **k):
        seen.extend(records if isinstance(records, list) else [records])
        raise FitError("stop: the test only looks at what the fit was given")

    from importlib import import_module

    monkeypatch.setattr(import_module("dtwin.identify.fit"), "fit", fake)
    monkeypatch.setattr(import_module("dtwin.identify.severity"), "estimate_severity", fake)
    for args in (["identify", str(path), "--preset", "paper-bench", "--free", "sun_fault"],
                 ["severity", str(path), "--preset", "paper-bench"],
                 ["identify", str(path), "--preset", "paper-bench", "--free", "sun_fault",
                  "--fit-window", "2:5"]):
        with pytest.raises(SystemExit) as e:
            main(args)
        assert e.value.code == 2
    assert [(r.duration, r.sample_rate) for r in seen] == [(4.0, 5120.0), (4.0, 5120.0),
                                                           (5.0, 5120.0)]
    assert seen[0].metadata["fit_window"]["start_s"] == pytest.approx(6.0)
    assert seen[2].metadata["fit_window"]["start_s"] == pytest.approx(2.0)
    capsys.readouterr()


def test_fleet_fits_the_window_of_a_long_record(spec, tmp_path, monkeypatch):
    """A fleet task hands the fit the same window (its problem is built from 4 s at 5120 Hz
    of a steady 12 s, 25.6 kHz record); a short record reaches it whole. (A record whose speed
    ramps is a run-up to the fleet, fitted whole as one.)"""
    from importlib import import_module

    from dtwin.errors import FitError
    from dtwin.identify.fleet import FleetSettings
    from dtwin.io.readers import write_record

    tasks = import_module("dtwin.identify.fleet.tasks")
    long_path = tmp_path / "long.dtwin.h5"
    write_record(_run(12.0, 1e-3, spec, tacho=True), long_path)  # steady
    seen = []

    def fake(rec, *a, **k):
        seen.append(rec)
        raise FitError("stop: the test only looks at what the fit was given")

    monkeypatch.setattr(tasks._fit, "make_problem", fake)
    jobs = [{"path": p, "key": k, "machine": "m", "timestamp": None, "identity_source": "test",
             "sha256": ""} for k, p in (("long", str(long_path)),
                                        ("short", "data/samples/bench_healthy.dtwin.h5"))]
    out = tasks.fit_task(jobs, preset("paper-bench").data, FleetSettings(free=("sun_fault",)),
                         fingerprint="test")
    assert [e["status"] for e in out] == ["failed", "failed"]
    assert (seen[0].duration, seen[0].sample_rate) == (4.0, 5120.0)
    assert seen[0].metadata["fit_window"]["chosen"] == "steadiest"
    assert (seen[1].duration, seen[1].sample_rate) == (4.0, 5000.0)
    assert "fit_window" not in seen[1].metadata
