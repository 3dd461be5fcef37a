"""Tests of dtwin.signal.spectrum: amplitudes against closed forms, scipy, JAX vs numpy, labels."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal

from dtwin.errors import RecordError
from dtwin.signal.spectrum import (
    WINDOWS,
    FrequencyBasis,
    amplitude_spectrum,
    analytic_signal,
    envelope_spectrum,
    find_peaks,
    get_window,
    label_frequency,
    label_peaks,
    level_at,
    noise_floor,
    time_stats,
    to_db,
    zoom,
)

FS = 1000.0
N = 2000  # df = 0.5 Hz


def _sine(amp, f, n=N, fs=FS, phase=0.3):
    t = np.arange(n) / fs
    return amp * np.sin(2 * np.pi * f * t + phase)


@pytest.mark.parametrize("win", sorted(WINDOWS))
def test_sine_on_bin_reads_its_amplitude_for_every_window(win):
    freqs, a = amplitude_spectrum(_sine(2.3, 50.0) + 0.7, FS, win)
    assert a[np.argmin(np.abs(freqs - 50.0))] == pytest.approx(2.3, rel=1e-9)
    assert a[0] == pytest.approx(0.7, rel=1e-9)  # DC is not doubled


@pytest.mark.parametrize("win", sorted(WINDOWS))
def test_amplitude_spectrum_matches_scipy_periodogram(win):
    # independent: scipy's "spectrum" scaling is RMS² per bin; amplitude = sqrt(2 P) off DC
    rng = np.random.default_rng(0)
    x = rng.normal(size=N)
    freqs, a = amplitude_spectrum(x, FS, win)
    f2, p = scipy.signal.periodogram(x, FS, window=WINDOWS[win], scaling="spectrum", detrend=False)
    np.testing.assert_allclose(freqs, f2)
    np.testing.assert_allclose(a[1:-1], np.sqrt(2 * p[1:-1]), rtol=1e-10)


def test_scalloping_closed_forms():
    # half a bin off: Hann keeps sinc(1/2)/(1 - 1/4) = 0.8488, rect sinc(1/2) = 2/pi
    f = 50.25
    for win, expected in (("hann", (2 / np.pi) / 0.75), ("rect", 2 / np.pi)):
        freqs, a = amplitude_spectrum(_sine(1.0, f, phase=0.0), FS, win)
        assert a.max() == pytest.approx(expected, rel=4e-3)  # + leakage of the -f image
    # flattop reads the amplitude off-bin within 0.1 %
    for f in (50.1, 50.25, 50.37):
        _, a = amplitude_spectrum(_sine(1.0, f), FS, "flattop")
        assert a.max() == pytest.approx(1.0, rel=2e-3)  # flattop scalloping < 0.02 dB


def test_jax_path_equals_numpy_path_and_is_differentiable():
    x = _sine(1.5, 120.0) + np.random.default_rng(1).normal(scale=0.1, size=N)
    f_np, a_np = amplitude_spectrum(x, FS, "hann")
    f_j, a_j = jax.jit(lambda v: amplitude_spectrum(v, FS, "hann"))(jnp.asarray(x))
    assert isinstance(a_j, jax.Array)
    np.testing.assert_allclose(np.asarray(a_j), a_np, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.asarray(analytic_signal(jnp.asarray(x))),
                               scipy.signal.hilbert(x), atol=1e-12)
    k = int(np.argmin(np.abs(f_np - 120.0)))

    def peak(amp):
        t = jnp.arange(N, dtype=jnp.float64) / FS
        return amplitude_spectrum(amp * jnp.sin(2 * jnp.pi * 120.0 * t + 0.3), FS, "hann")[1][k]

    # closed form: d(peak)/d(amp) = 1 for an on-bin tone; also central finite differences
    g = jax.grad(peak)(2.0)
    fd = (peak(2.0 + 1e-4) - peak(2.0 - 1e-4)) / 2e-4
    assert float(g) == pytest.approx(1.0, rel=1e-9)
    assert float(g) == pytest.approx(float(fd), rel=1e-7)
    _, e_np = envelope_spectrum(x, FS)
    _, e_j = envelope_spectrum(jnp.asarray(x), FS)
    np.testing.assert_allclose(np.asarray(e_j), e_np, atol=1e-12)


def test_envelope_spectrum_reads_modulation_depth():
    t = np.arange(N) / FS
    x = (1 + 0.4 * np.cos(2 * np.pi * 10.0 * t)) * np.cos(2 * np.pi * 200.0 * t)
    freqs, e = envelope_spectrum(x, FS, "hann")
    assert level_at(freqs, e, 10.0) == pytest.approx(0.4, rel=1e-6)
    assert e[0] < 1e-12  # mean removed


@pytest.mark.parametrize("win", ["rect", "hann", "flattop"])
def test_noise_floor_of_white_noise_matches_rayleigh_median(win):
    # amplitude of a bin of white noise is Rayleigh; its median is 2 sigma sqrt(ln2 sum w^2)/sum w
    sigma, n = 0.3, 1 << 15
    x = np.random.default_rng(2).normal(scale=sigma, size=n)
    _, a = amplitude_spectrum(x, FS, win)
    w = get_window(win, n)
    theory = 2 * sigma * np.sqrt(np.log(2) * np.sum(w * w)) / w.sum()
    floor = noise_floor(a, 31)
    assert np.median(floor) == pytest.approx(theory, rel=0.03)


def test_to_db_and_floor_never_log_zero():
    spec = np.array([0.0, 1.0, 10.0, 0.0])
    db = to_db(spec)
    assert np.all(np.isfinite(db))
    np.testing.assert_allclose(db[1:3], [0.0, 20.0])
    assert db[0] == pytest.approx(20 * np.log10(10.0 * 1e-12))
    np.testing.assert_allclose(to_db(spec, ref=10.0, floor=0.1), [-40, -20, 0, -40])
    assert np.all(noise_floor(np.zeros(50)) > 0)
    np.testing.assert_allclose(np.asarray(to_db(jnp.asarray(spec))), db)


def test_zoom_level_at_and_errors():
    freqs = np.arange(11.0)
    spec = np.arange(11.0) ** 2
    f, s = zoom(freqs, spec, (2.5, 5.0))
    np.testing.assert_array_equal(f, [3, 4, 5])
    np.testing.assert_array_equal(s, [9, 16, 25])
    assert level_at(freqs, spec, 4.2) == 25.0  # max within ±1 bin of bin 4
    with pytest.raises(RecordError, match="band"):
        zoom(freqs, spec, (20, 30))
    with pytest.raises(RecordError, match="window"):
        amplitude_spectrum(np.ones(8), 10.0, "kaiser9")


def test_time_stats_of_a_sine():
    t = np.arange(1000) / 1000.0
    x = 3.0 * np.sin(2 * np.pi * 7 * t)
    s = time_stats(x)
    assert s.rms == pytest.approx(3 / np.sqrt(2))
    assert s.kurtosis == pytest.approx(1.5)
    assert s.crest_factor == pytest.approx(np.sqrt(2), rel=1e-6)


# Simulation gearbox of the paper (docs/references.md §1): Zs 21, Zp 30, Zr 81, N 3, 1800 rpm input.
F_SUN = 30.0
FC = F_SUN * 21 / (21 + 81)
FM = FC * 81
BASIS = FrequencyBasis(f_mesh=FM, f_carrier=FC, f_sun_fault=FM * 3 / 21, f_planet_fault=FM / 30,
                       n_planets=3)


def test_sideband_family_detected_and_labelled_like_the_paper():
    fs_rate, dur = 5000.0, 4.0
    t = np.arange(int(fs_rate * dur)) / fs_rate
    fsn, fp = BASIS.f_sun_fault / 3, BASIS.f_planet_fault
    lines = {  # frequency: (amplitude, expected label)
        FM: (1.0, "fm"),
        FM - FC: (0.2, "fm − fc"),
        FM + FC: (0.15, "fm + fc"),
        FM - 7 * FC: (0.05, "fm − 7fc"),
        FM + 7 * FC: (0.04, "fm + 7fc"),
        FM + fsn + FC: (0.08, "fm + fs/3 + fc"),
        FM - fsn - FC: (0.06, "fm − fs/3 − fc"),
        FM + 2 * fp + FC: (0.03, "fm + 2fp + fc"),
        FM - fp: (0.03, "fm − fp"),
    }
    rng = np.random.default_rng(3)
    x = sum(a * np.cos(2 * np.pi * f * t + rng.uniform(0, 6)) for f, (a, _) in lines.items())
    x = x + rng.normal(scale=0.01, size=t.size)
    freqs, spec = amplitude_spectrum(x, fs_rate, "hann")
    peaks = find_peaks(freqs, spec, threshold_db=15.0, band=(450, 550), width_bins=61)
    labelled = label_peaks(peaks, BASIS, resolution=freqs[1] - freqs[0])
    assert len(labelled) == len(lines)
    for lp, (f, (amp, text)) in zip(labelled, sorted(lines.items()), strict=True):
        assert abs(lp.peak.frequency - f) <= freqs[1] - freqs[0]
        assert lp.peak.amplitude == pytest.approx(amp, rel=0.2)  # Hann scalloping < 15 %
        assert lp.labels[0].text == text
        assert len(lp.labels) == 1
    assert [lp.number for lp in labelled] == list(range(1, len(lines) + 1))


def test_label_ties_are_reported_and_ranked_by_order():
    # a basis where fs/3 equals fp: "fm + fs/3" and "fm + fp" tie at order 2
    basis = FrequencyBasis(f_mesh=500.0, f_carrier=6.0, f_sun_fault=3 * 17.0,
                           f_planet_fault=17.0, n_planets=3)
    cands = label_frequency(517.0, basis, 0.1)
    best = [c for c in cands if c.order == cands[0].order]
    assert sorted(c.text for c in best) == ["fm + fp", "fm + fs/3"]
    assert all(c.order >= 2 for c in cands)
    # the bench gearbox: fs/3 = 4 fc exactly, the lower order wins over "fm + 4fc"
    bench = FrequencyBasis(f_mesh=84 * 5.94, f_carrier=5.94, f_sun_fault=84 * 5.94 * 3 / 21)
    cands = label_frequency(88 * 5.94, bench, 0.05)
    assert cands[0].text == "fm + fs/3" and cands[0].order == 2
    assert "fm + 4fc" in [c.text for c in cands]


def test_find_peaks_min_spacing_keeps_the_higher():
    t = np.arange(4000) / 1000.0
    x = np.cos(2 * np.pi * 100 * t) + 0.5 * np.cos(2 * np.pi * 101 * t)
    x = x + np.random.default_rng(4).normal(scale=1e-3, size=t.size)
    freqs, a = amplitude_spectrum(x, 1000.0, "hann")
    assert len(find_peaks(freqs, a, threshold_db=20)) == 2
    p = find_peaks(freqs, a, threshold_db=20, min_spacing_hz=2.0)
    assert [q.frequency for q in p] == [100.0]


def test_cepstrum_shows_a_sideband_family_as_rahmonics():
    from dtwin.signal.cepstrum import rahmonics, real_cepstrum

    fs, dur, spacing = 5000.0, 4.0, 3 * FC  # fm ± k N fc: the planet-pass family (reference §2)
    t = np.arange(int(fs * dur)) / fs
    x = sum(np.cos(2 * np.pi * (FM + k * spacing) * t) * 0.8 ** abs(k) for k in range(-6, 7))
    x = x + np.random.default_rng(6).normal(scale=1e-3, size=t.size)
    q, c = real_cepstrum(x, sample_rate=fs)
    sel = (q > 0.01) & (q < 0.2)
    assert q[sel][np.argmax(c[sel])] == pytest.approx(1 / spacing, abs=2 / fs)
    r = rahmonics(q, c, spacing, 3)
    assert r[0] > 5 * np.std(c[sel])


# --- the CLI: dtwin spectrum on a record written with the native writer -------------------------


def _write_native(tmp_path, x, fs, **kw):
    readers = pytest.importorskip("dtwin.io.readers", reason="record readers not available yet")
    from dtwin.io import Record

    path = tmp_path / "rec.dtwin.h5"
    readers.write_record(Record(np.asarray(x)[None, :], fs, ("acc",), ("m/s^2",), **kw), path)
    return path


def test_cli_spectrum_labels_the_paper_family(tmp_path, capsys):
    pytest.importorskip("dtwin.model.gears", reason="dtwin.model.gears not available yet")
    pytest.importorskip("dtwin.spec", reason="dtwin.spec not available yet")
    import json

    from dtwin.cli import main

    fs = 5000.0
    t = np.arange(int(4 * fs)) / fs
    x = (np.cos(2 * np.pi * FM * t) + 0.1 * np.cos(2 * np.pi * (FM - 7 * FC) * t)
         + 0.08 * np.cos(2 * np.pi * (FM + BASIS.f_sun_fault / 3 + FC) * t)
         + np.random.default_rng(7).normal(scale=0.01, size=t.size))
    path = _write_native(tmp_path, x, fs)
    out = tmp_path / "out"
    main(["spectrum", str(path), "--preset", "paper-sim", "--f-sun", str(F_SUN), "--json"])
    rep = json.loads(capsys.readouterr().out)
    # the default band: the gearbox's mesh harmonics with 12 carrier sidebands each side
    assert rep["band_hz"] == pytest.approx([FM - 12 * FC, 3 * FM + 12 * FC])
    main(["spectrum", str(path), "--preset", "paper-sim", "--f-sun", str(F_SUN), "--json",
          "--band", "450", "550", "--out", str(out)])
    rep = json.loads(capsys.readouterr().out)
    assert [p["labels"][0] for p in rep["peaks"]] == ["fm − 7fc", "fm", "fm + fs/3 + fc"]
    assert rep["frequencies_hz"]["f_mesh"] == pytest.approx(FM)
    assert rep["time_stats"]["rms"] == pytest.approx(np.sqrt(np.mean(x**2)))
    assert {"spectrum.png", "waveform.png", "spectrum.json", "manifest.json"} <= {
        p.name for p in out.iterdir()}
    # without a gearbox: peaks found, unlabelled; an unknown channel is a clear error
    main(["spectrum", str(path), "--json", "--band", "450", "550"])
    rep = json.loads(capsys.readouterr().out)
    assert len(rep["peaks"]) == 3 and all(p["labels"] == [] for p in rep["peaks"])
    with pytest.raises(SystemExit) as e:
        main(["spectrum", str(path), "--channel", "nope"])
    assert e.value.code == 2
    assert "unknown channel" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["spectrum", str(path), "--band", "2000", "3000"])  # above Nyquist (2500 Hz)
    assert "half the record's sampling rate" in capsys.readouterr().err


def test_bench_degeneracy_is_reported_as_an_alternative():
    # bench gearbox (Zs 21, Zr 84): fs/3 = 4 fc exactly, so fm + fs/3 + fc = fm + 5fc
    fc = 29.7 * 21 / 105
    bench = FrequencyBasis(f_mesh=84 * fc, f_carrier=fc, f_sun_fault=84 * fc * 3 / 21,
                           f_planet_fault=84 * fc / 31)
    from dtwin.signal.spectrum import Peak

    peak = Peak(0, 89 * fc, 1.0, 0.01, 40.0)
    (lp,) = label_peaks([peak], bench, resolution=0.25)
    assert lp.text == "fm + 5fc"
    assert "fm + fs/3 + fc" in [a.text for a in lp.alternatives]
    assert lp.n_alternatives == len(lp.alternatives) > 0
