"""Tests of dtwin.signal.tsa: comb-filter closed form, sqrt(n) noise suppression, planet separation."""

import numpy as np
import pytest

from dtwin.errors import RecordError
from dtwin.io import Record
from dtwin.signal.indicators import fm4
from dtwin.signal.tsa import planet_separation, sun_relative_angle, time_synchronous_average

ZS, ZP, ZR, N = 21, 30, 81, 3  # the paper's simulation gearbox (docs/references.md §1)


def _sun_fault_signature(rel_angle):
    """N impacts per revolution of the sun relative to the carrier (one per planet met)."""
    ph = np.mod(rel_angle * N / (2 * np.pi), 1.0)  # fraction of the way between two planets
    return np.exp(-(((ph - 0.5) / 0.01) ** 2))


def test_tsa_keeps_the_sun_fault_signature_and_suppresses_noise_by_sqrt_n():
    # constant speed chosen so the angle grid falls on the samples: fs / f_rel = 256 points/rev
    fs, f_rel, n_rev = 5120.0, 20.0, 64
    t = np.arange(int(n_rev * fs / f_rel)) / fs
    f_carrier = f_rel * ZS / ZR
    carrier = 2 * np.pi * f_carrier * t
    rel = sun_relative_angle(carrier, ZS, ZR)
    np.testing.assert_allclose(rel, 2 * np.pi * f_rel * t)  # kinematics, ring fixed
    sigma = 0.4
    rng = np.random.default_rng(0)
    signature = _sun_fault_signature(rel)
    async_order = 7.3  # a line not locked to the sun-carrier rotation
    x = signature + 0.5 * np.cos(async_order * rel) + rng.normal(scale=sigma, size=t.size)
    rec = Record(x[None, :], fs, ("acc",), ("m/s^2",))
    tsa = time_synchronous_average(rec, rel, 256, anti_alias=False)
    assert tsa.n_averages == n_rev
    truth = _sun_fault_signature(tsa.angle)
    assert np.corrcoef(tsa.average, truth)[0, 1] > 0.9  # one revolution alone: 0.1-0.25
    # the TSA is linear: average each part on its own
    noise = rng.normal(scale=sigma, size=t.size)
    tsa_noise = time_synchronous_average(noise, rel, 256, sample_rate=fs, anti_alias=False)
    assert np.std(tsa_noise.average) == pytest.approx(sigma / np.sqrt(n_rev), rel=0.15)
    tsa_sig = time_synchronous_average(signature + noise, rel, 256, sample_rate=fs,
                                       anti_alias=False)
    # signature-to-noise ratio: one revolution vs the average, gain sqrt(n)
    snr_one = np.ptp(truth) / np.std(tsa_sig.revolutions[3] - truth)
    snr_avg = np.ptp(truth) / np.std(tsa_sig.average - truth)
    assert snr_avg / snr_one == pytest.approx(np.sqrt(n_rev), rel=0.2)
    # the asynchronous line: comb gain |sin(pi n r) / (n sin(pi r))| (McFadden 1987)
    tsa_line = time_synchronous_average(0.5 * np.cos(async_order * rel), rel, 256,
                                        sample_rate=fs, anti_alias=False)
    comb = abs(np.sin(np.pi * n_rev * async_order) / (n_rev * np.sin(np.pi * async_order)))
    assert np.sqrt(2) * np.std(tsa_line.average) == pytest.approx(0.5 * comb, abs=0.01)


def test_tsa_attenuates_an_asynchronous_tone_by_the_comb_gain():
    fs, f_shaft, n_rev = 4096.0, 16.0, 40  # 256 samples per revolution exactly
    t = np.arange(int(n_rev * fs / f_shaft)) / fs
    ang = 2 * np.pi * f_shaft * t
    for r in (3.0, 5.25, 9.5, 11.9):
        tsa = time_synchronous_average(np.cos(r * ang), ang, 256, sample_rate=fs, anti_alias=False)
        expected = abs(np.sin(np.pi * n_rev * r) / (n_rev * np.sin(np.pi * r))) if r % 1 else 1.0
        # the average's RMS against that of a unit line attenuated by the comb gain
        assert np.sqrt(2) * np.std(tsa.average) == pytest.approx(expected, abs=0.02)


def _planet_signal(carrier, faulty, seed=1):
    """Sensor signal for a carrier angle history: each planet's ring mesh seen through a window
    of its angle to the sensor (on top, pi/2); planet `faulty` has a damaged tooth 7."""
    psi = 2 * np.pi * np.arange(N) / N
    x = np.zeros_like(carrier)
    for i in range(N):
        q = ZR * (carrier + psi[i]) / (2 * np.pi)  # ring-mesh cycles of planet i (conventions)
        mesh = np.cos(2 * np.pi * q)
        if i == faulty:  # an impulse each time the damaged tooth meshes with the ring
            mesh = mesh + 1.5 * np.exp(-(((np.mod(q, ZP) - 7.5) / 0.08) ** 2))
        phi = np.angle(np.exp(1j * (carrier + psi[i] - np.pi / 2)))  # planet angle to the sensor
        x += np.exp(-0.5 * (phi / 0.5) ** 2) * mesh  # transfer path: strongest under the sensor
    return x + np.random.default_rng(seed).normal(scale=0.1, size=carrier.size)


def _planet_record(faulty, fs=5000.0, duration=4.0, f_carrier=6.0, seed=1):
    t = np.arange(int(fs * duration)) / fs
    carrier = 2 * np.pi * f_carrier * t
    return _planet_signal(carrier, faulty, seed), carrier, fs


@pytest.mark.parametrize("faulty", [0, 1, 2])
def test_planet_separation_points_at_the_faulty_planet(faulty):
    x, carrier, fs = _planet_record(faulty)
    sep = planet_separation(x, carrier, ZR, ZP, N, sample_rate=fs)
    assert sep.complete
    assert sep.window_teeth == 6.0  # 2 gcd(81, 30)
    assert np.all(sep.n_passes >= ZP // 3)
    ind = [fm4(a, ZP) for a in sep.averages]
    assert int(np.argmax(ind)) == faulty
    others = [v for i, v in enumerate(ind) if i != faulty]
    assert ind[faulty] > 2 * max(others)
    # the impulse sits at the damaged tooth's position
    peak_tooth = sep.tooth[np.argmax(sep.averages[faulty] - np.cos(2 * np.pi * sep.tooth))]
    assert abs(peak_tooth - 7.5) < 0.2


def test_hann_windows_of_width_2g_are_a_partition_of_unity():
    # McFadden 1994: the weights over the centres visited sum to a constant per position
    x, carrier, fs = _planet_record(None, duration=1.0 / 6.0 * ZP * 2)  # 2 full covering cycles
    sep = planet_separation(x, carrier, ZR, ZP, N, sample_rate=fs)
    w = sep.weights[0]
    assert np.std(w) / np.mean(w) < 0.05


def test_too_short_record_is_refused():
    t = np.arange(100) / 1000.0
    with pytest.raises(RecordError, match="two whole"):
        time_synchronous_average(np.sin(t), 2 * np.pi * t, 64, sample_rate=1000.0)
    with pytest.raises(RecordError, match="sample_rate"):
        time_synchronous_average(np.sin(t), 2 * np.pi * t, 64)


def test_cli_view_tsa_finds_the_faulty_planet_with_a_carrier_tacho(tmp_path, capsys):
    readers = pytest.importorskip("dtwin.io.readers", reason="record readers not available yet")
    pytest.importorskip("dtwin.spec", reason="dtwin.spec not available yet")
    import json

    from dtwin.cli import main

    fs, f_carrier = 5000.0, 6.0
    t = np.arange(int(fs * 4.0)) / fs
    carrier = 2 * np.pi * f_carrier * t - 0.3  # the tacho's first rising edge is carrier angle 0
    x = _planet_signal(carrier, faulty=2, seed=3)
    tacho = np.sin(carrier)  # a once-per-revolution pick-up on the carrier
    path = tmp_path / "planets.dtwin.h5"
    readers.write_record(Record(x[None, :], fs, ("acc",), ("m/s^2",), tacho=tacho,
                                tacho_ppr=1, tacho_shaft="carrier"), path)
    out = tmp_path / "tsa"
    main(["view", str(path), "--kind", "tsa", "--preset", "paper-sim", "--json", "--out", str(out)])
    rep = json.loads(capsys.readouterr().out)
    assert {"tsa.png", "tsa_sun.png", "planets.png", "view_tsa.json"} <= {p.name for p in out.iterdir()}
    assert rep["planets"]["numbering"] == "absolute"
    assert rep["planets"]["largest_fm4"] == 2
    assert rep["f_sun_hz"] == pytest.approx(f_carrier * (ZS + ZR) / ZS, rel=1e-3)
