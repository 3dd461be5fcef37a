"""Tests of dtwin.signal.envelope: the kurtogram finds a fault's resonance; envelope spectra."""

import numpy as np
import pytest

from dtwin.errors import RecordError
from dtwin.io import Record
from dtwin.signal.envelope import bandpass, envelope, envelope_spectrum, fast_kurtogram
from dtwin.signal.spectrum import amplitude_spectrum, find_peaks, level_at

FS = 5000.0
F_RES = 1700.0  # structural resonance rung by the fault
F_FAULT = 37.0  # impacts per second


@pytest.fixture(scope="module")
def impulsive():
    """Decaying-resonance impulses at F_FAULT + a strong mesh tone + white noise."""
    t = np.arange(int(2.0 * FS)) / FS
    rng = np.random.default_rng(0)
    x = 3.0 * np.sin(2 * np.pi * 500.0 * t) + 1.0 * np.sin(2 * np.pi * 1000.0 * t + 0.3)
    tau = 2e-3
    for t0 in np.arange(0.01, t[-1], 1 / F_FAULT):
        d = np.clip(t - t0, 0.0, None)
        x += np.where(t >= t0, 2.0 * np.exp(-d / tau) * np.sin(2 * np.pi * F_RES * d), 0.0)
    x += rng.normal(scale=0.3, size=t.size)
    return t, x


def test_kurtogram_picks_the_resonance_band(impulsive):
    _, x = impulsive
    kg = fast_kurtogram(x, sample_rate=FS)
    lo, hi = kg.best_band
    assert lo <= F_RES <= hi
    assert kg.best_bandwidth <= FS / 4  # a band, not the whole spectrum
    assert kg.best_kurtosis > 1.0
    # Gaussian noise alone: every band's kurtosis near 0 (complex envelope, Antoni 2007)
    noise = np.random.default_rng(1).normal(size=x.size)
    kn = fast_kurtogram(noise, sample_rate=FS)
    assert np.nanmax(np.abs(kn.kurtosis[:4])) < 0.2
    # the rows follow the 1/3-binary tree: 1, 2, 3, 4, 6, 8 … bands
    assert list(kg.n_bands[:6]) == [1, 2, 3, 4, 6, 8]
    np.testing.assert_allclose(kg.levels[:3], [0, 1, np.log2(3)])


def test_envelope_spectrum_of_the_picked_band_shows_the_fault_rate(impulsive):
    _, x = impulsive
    rec = Record(x[None, :], FS, ("acc",), ("m/s^2",))
    band = fast_kurtogram(rec).best_band
    freqs, e = envelope_spectrum(rec, band)
    peaks = find_peaks(freqs, e, threshold_db=10, band=(5, 200))
    strongest = max(peaks, key=lambda p: p.amplitude)
    assert abs(strongest.frequency - F_FAULT) <= freqs[1] - freqs[0]
    # the raw (whole-band) envelope is dominated by the mesh tones and hides the fault rate
    f_raw, e_raw = envelope_spectrum(x, sample_rate=FS)
    assert level_at(f_raw, e_raw, F_FAULT) < level_at(freqs, e, F_FAULT)


def test_bandpass_and_envelope_of_an_am_tone():
    t = np.arange(10000) / FS
    x = (1 + 0.5 * np.cos(2 * np.pi * 20 * t)) * np.cos(2 * np.pi * 1200 * t) + np.sin(2 * np.pi * 100 * t)
    y = bandpass(x, (1000, 1400), sample_rate=FS)
    f, a = amplitude_spectrum(y, FS)
    assert level_at(f, a, 100.0) < 1e-4  # out of band: gone
    assert level_at(f, a, 1200.0) == pytest.approx(1.0, rel=1e-3)  # in band: kept (zero phase)
    env = envelope(x, (1000, 1400), sample_rate=FS)
    mid = slice(1000, -1000)
    np.testing.assert_allclose(env[mid], 1 + 0.5 * np.cos(2 * np.pi * 20 * t[mid]), atol=5e-3)
    f, e = envelope_spectrum(x, (1000, 1400), sample_rate=FS)
    assert level_at(f, e, 20.0) == pytest.approx(0.5, rel=0.01)


def test_bad_band_is_refused():
    with pytest.raises(RecordError, match="band"):
        bandpass(np.ones(100), (3000, 4000), sample_rate=FS)


def test_cli_view_envelope_and_kurtogram(impulsive, tmp_path, capsys):
    readers = pytest.importorskip("dtwin.io.readers", reason="record readers not available yet")
    import json

    from dtwin.cli import main

    _, x = impulsive
    path = tmp_path / "imp.dtwin.h5"
    readers.write_record(Record(x[None, :], FS, ("acc",), ("m/s^2",)), path)
    main(["view", str(path), "--kind", "kurtogram", "--json"])
    lo, hi = json.loads(capsys.readouterr().out)["best_band_hz"]
    assert lo <= F_RES <= hi
    out = tmp_path / "env"
    main(["view", str(path), "--kind", "envelope", "--json", "--out", str(out)])
    rep = json.loads(capsys.readouterr().out)
    assert rep["band_source"].startswith("kurtogram")
    assert rep["band_hz"] == [lo, hi]
    assert (out / "envelope.png").exists() and (out / "view_envelope.json").exists()
    main(["view", str(path), "--kind", "cepstrum", "--json"])
    assert json.loads(capsys.readouterr().out)["quefrency_resolution_s"] == pytest.approx(1 / FS)


def test_kurtogram_figure_outlines_the_picked_band(impulsive):
    from matplotlib.patches import Rectangle

    from dtwin.plotting.views import plot_kurtogram

    _, x = impulsive
    kg = fast_kurtogram(x, sample_rate=FS)
    fig = plot_kurtogram(kg)
    ax = fig.axes[0]
    outlined = [p for p in ax.patches if isinstance(p, Rectangle) and not p.get_fill()]
    assert len(outlined) == 1
    assert outlined[0].get_x() == pytest.approx(kg.best_band[0])
    assert outlined[0].get_width() == pytest.approx(kg.best_bandwidth)
    # one coloured cell per band of the tree (a mesh per level), and axis labels with units
    from matplotlib.collections import QuadMesh

    meshes = [c for c in ax.collections if isinstance(c, QuadMesh)]
    assert [m.get_array().size for m in meshes] == [int(n) for n in kg.n_bands]

    assert ax.get_xlabel() == "frequency (Hz)"


def _ideal_band_kurtosis(x, fs, lo, hi, last):
    """Kurtosis of the complex envelope of the ideal (brick-wall) band [lo, hi) Hz: the band's
    bins of the full-length FFT, inverse-transformed on all N points (an independent route)."""
    n = x.size
    spec = np.fft.fft(x - x.mean())
    freqs = np.fft.fftfreq(n, 1.0 / fs)
    sel = (freqs >= lo) & ((freqs <= hi) if last else (freqs < hi))
    p = np.abs(np.fft.ifft(np.where(sel, spec, 0.0))) ** 2
    return np.mean(p * p) / np.mean(p) ** 2 - 2.0


def test_kurtogram_filter_bank_agrees_with_ideal_bands():
    """Noise with impulses ringing a resonance centred in one level-3 band: the filter bank
    picks that band, as ideal bands do, and its kurtosis map agrees with the ideal bands'
    within 0.3 (1 + |K|): the FIR bands are 6 dB down at their edges and pass a share of the
    neighbouring bands' power (module docstring of dtwin.signal.envelope); with 2**15 samples the
    estimator's own scatter is below 0.05 on these rows."""
    fs, n = 10000.0, 2**15
    rng = np.random.default_rng(5)
    x = rng.standard_normal(n)
    f_res, zeta = 3437.5, 0.02  # centre of band 5 of 8 (3125-3750 Hz)
    tt = np.arange(int(0.02 * fs)) / fs
    ring = np.exp(-2 * np.pi * f_res * zeta * tt) * np.sin(2 * np.pi * f_res * tt)
    pulses = np.zeros(n)
    pulses[(np.arange(0.01, n / fs, 1 / 23.0) * fs).astype(int)] = 4.0
    x += np.convolve(pulses, ring)[:n]
    kg = fast_kurtogram(x, sample_rate=fs, max_level=3)
    ideal = np.full_like(kg.kurtosis, np.nan)
    for r, nb in enumerate(kg.n_bands):
        w = fs / 2 / nb
        for b in range(nb):
            ideal[r, b] = _ideal_band_kurtosis(x, fs, b * w, (b + 1) * w, b == nb - 1)
    r_best, b_best = np.unravel_index(np.nanargmax(ideal), ideal.shape)
    assert kg.best_level == pytest.approx(np.log2(kg.n_bands[r_best]))
    w = fs / 2 / kg.n_bands[r_best]
    assert kg.best_band == pytest.approx((b_best * w, (b_best + 1) * w))
    assert kg.best_band == pytest.approx((3125.0, 3750.0))
    np.testing.assert_array_equal(np.isnan(kg.kurtosis), np.isnan(ideal))
    ok = np.isfinite(ideal)
    assert np.all(np.abs(kg.kurtosis[ok] - ideal[ok]) <= 0.3 * (1 + np.abs(ideal[ok])))
    # level 0 is the analytic signal of the whole record in both (up to the Nyquist bin,
    # which scipy.signal.hilbert keeps and the band [0, fs/2) of fftfreq leaves out)
    assert kg.kurtosis[0, 0] == pytest.approx(ideal[0, 0], rel=1e-3)


def test_kurtogram_closed_forms_tone_and_gaussian_noise():
    """A pure tone's complex envelope is constant: K = -1 in every band holding the tone;
    Gaussian noise has a complex Gaussian envelope in every band: E|c|^4 = 2 (E|c|^2)^2, K = 0
    within the estimator's scatter (delta method for M samples of |c|^2 ~ Exp: var 4/M, the
    node's samples being correlated pairwise: 8/M)."""
    fs, n = 1000.0, 2**16
    f0 = 203.7  # no bin frequency: the record does not hold whole periods
    tone = np.cos(2 * np.pi * f0 * np.arange(n) / fs)
    kg = fast_kurtogram(tone, sample_rate=fs, max_level=6)
    for r, nb in enumerate(kg.n_bands):
        w = fs / 2 / nb
        b = int(f0 // w)
        # level 0 (the FFT's analytic signal) sees the wrap-around of a record that holds no
        # whole number of periods; in the filter bank's rows the tone's negative-frequency
        # image leaks through the stop band (-70 dB: amplitude e <= 3.2e-4), a beat that moves
        # K by 2 e^2 <= 2e-7
        assert kg.kurtosis[r, b] == pytest.approx(-1.0, abs=1e-4 if nb == 1 else 1e-6), (nb, b)
    noise = np.random.default_rng(7).standard_normal(n)
    kn = fast_kurtogram(noise, sample_rate=fs, max_level=6)
    for r, nb in enumerate(kn.n_bands):
        m = n / nb  # samples per band (2x the band's width)
        sigma = np.sqrt(8.0 / m)
        row = kn.kurtosis[r, :nb]
        assert np.all(np.abs(row) < 5 * sigma), (nb, row)
        assert abs(row.mean()) < 5 * sigma / np.sqrt(nb), (nb, row.mean())


def test_kurtogram_of_a_constant_record_is_refused():
    with pytest.raises(RecordError, match="constant"):
        fast_kurtogram(np.full(1000, 2.0), sample_rate=FS)
