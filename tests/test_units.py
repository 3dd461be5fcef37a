"""Units: scale factors, integration to velocity/displacement against closed forms, dB
references (ISO 1683), ISO 20816-3 zones."""

import numpy as np
import pytest

from dtwin.errors import RecordError
from dtwin.signal import units


def test_standard_gravity():
    # 1 g = 9.80665 m/s² (CGPM 1901, ISO 80000-3)
    x = np.array([9.80665, -19.6133])
    np.testing.assert_allclose(units.convert_signal(x, 1000.0, "m/s²", "g"), [1.0, -2.0])
    np.testing.assert_allclose(units.convert_signal([1.0], 1000.0, "g", "mm/s^2"), [9806.65])


@pytest.mark.parametrize("f0", [50.0, 123.4])
def test_sine_integrates_to_velocity_and_displacement(f0):
    # a sin(2 pi f t)  ->  v = -a/(2 pi f) cos(2 pi f t),  d = -a/(2 pi f)^2 sin(2 pi f t)
    fs, n = 5000.0, 50_000  # 10 s: f0 on a bin (0.1 Hz resolution)
    t = np.arange(n) / fs
    a = 3.0
    x = a * np.sin(2 * np.pi * f0 * t)
    w = 2 * np.pi * f0
    hp = 1 / np.sqrt(1 + (10.0 / f0) ** 8)  # the stated 4th-order 10 Hz high-pass
    v = units.convert_signal(x, fs, "m/s^2", "mm/s", highpass_hz=10.0)
    np.testing.assert_allclose(v, -1e3 * hp * a / w * np.cos(w * t), atol=1e-9 * 1e3 * a / w)
    d = units.convert_signal(x, fs, "m/s^2", "um")
    np.testing.assert_allclose(d, -1e6 * hp * a / w**2 * np.sin(w * t), atol=1e-9 * 1e6 * a / w**2)
    # back again: differentiate velocity to acceleration
    back = units.convert_signal(v, fs, "mm/s", "m/s^2")
    np.testing.assert_allclose(back, hp * x, atol=1e-9 * a)


def test_highpass_removes_low_frequencies():
    fs, n = 1000.0, 10_000
    t = np.arange(n) / fs
    x = np.sin(2 * np.pi * 1.0 * t) + 0.1  # 1 Hz and an offset: below the 10 Hz high-pass
    v = units.convert_signal(x, fs, "m/s^2", "m/s", highpass_hz=10.0, highpass_order=4)
    # |H(1 Hz)| = 1/sqrt(1 + 10^8) = 1e-4;  amplitude 1/(2 pi) * 1e-4
    assert np.max(np.abs(v)) == pytest.approx(1e-4 / (2 * np.pi), rel=1e-3)


def test_spectrum_conversion_matches_signal_conversion():
    f = np.array([0.0, 20.0, 100.0])
    a = np.array([1.0, 2.0, 2.0])
    v = units.convert_spectrum(f, a, "m/s^2", "mm/s", highpass_hz=10.0)
    hp = 1 / np.sqrt(1 + (10 / f[1:]) ** 8)
    np.testing.assert_allclose(v, [0.0, *(1e3 * a[1:] / (2 * np.pi * f[1:]) * hp)])


def test_db_references_iso1683():
    assert units.db_reference("m/s^2") == (pytest.approx(1e-6), "1 µm/s²")
    assert units.db_reference("mm/s") == (pytest.approx(1e-6), "1 nm/s")  # 1 nm/s in mm/s
    assert units.db_reference("g") == (1.0, "1 g")
    assert units.db_reference("V") == (1.0, "1 V")
    lv, text = units.to_db(np.array([1.0]), "m/s²")
    assert lv[0] == pytest.approx(120.0) and text == "dB re 1 µm/s²"


def test_iso20816_zones():
    # ISO 20816-3:2022 Annex A (= ISO 10816-3 Tables A.1, A.2), mm/s RMS
    z = units.iso20816_zones(2, "rigid")
    assert (z.ab, z.bc, z.cd) == (1.4, 2.8, 4.5)
    z1 = units.iso20816_zones(1, "flexible")
    assert (z1.ab, z1.bc, z1.cd) == (3.5, 7.1, 11.0)
    assert [units.iso20816_zone(v, z) for v in (1.0, 1.4, 3.0, 4.5)] == ["A", "B", "C", "D"]
    with pytest.raises(RecordError):
        units.iso20816_zones(3, "rigid")


def test_broadband_velocity_rms():
    # a 100 Hz acceleration sine of amplitude A: velocity RMS A/(2 pi 100)/sqrt(2)
    fs, n = 5000.0, 50_000
    t = np.arange(n) / fs
    a = 5.0
    x = a * np.sin(2 * np.pi * 100 * t) + 2.0 * np.sin(2 * np.pi * 2000 * t)  # 2 kHz: out of band
    v = units.broadband_velocity_rms(x, fs, "m/s^2")
    assert v == pytest.approx(1e3 * a / (2 * np.pi * 100) / np.sqrt(2), rel=1e-6)


def test_unknown_unit_refused():
    with pytest.raises(RecordError, match="not a vibration unit"):
        units.convert_signal(np.zeros(8), 100.0, "V", "g")
    assert units.normalise_unit("µm") == "um" and units.normalise_unit("m/s2") == "m/s^2"


def test_a_records_unit_says_what_the_twin_simulates():
    """Fits, calibration and discovery simulate what the record's channel measures where its
    unit says (a velocity record in mm/s is fitted as velocity, not as acceleration with a
    gain); where it does not (volts, no unit) the fit takes acceleration and calibration the
    spec's `sensor.quantity`."""
    from dtwin.identify.calibrate import _quantity
    from dtwin.identify.residuals import quantity_of_unit
    from dtwin.spec import load_spec, preset, spec_to_dict

    for unit, q in (("mm/s", "velocity"), ("m/s", "velocity"), ("g", "acceleration"),
                    ("m/s²", "acceleration"), ("µm", "displacement"), ("V", "acceleration"),
                    ("", "acceleration")):
        assert quantity_of_unit(unit) == q, unit
    data = spec_to_dict(preset("paper-sim"))
    data.pop("source")
    acc = load_spec({**data, "sensor": {**data["sensor"], "quantity": "acceleration"}})
    vel = load_spec({**data, "sensor": {**data["sensor"], "quantity": "velocity"}})
    assert _quantity(acc, "mm/s") == "velocity" and _quantity(vel, "g") == "acceleration"
    assert _quantity(acc, "V") == "acceleration" and _quantity(vel, None) == "velocity"
