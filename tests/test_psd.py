"""Tests of dtwin.signal.psd: Parseval for tones and white noise, for every window offered."""

import numpy as np
import pytest

from dtwin.errors import RecordError
from dtwin.signal.psd import (
    WINDOWS,
    averaged_amplitude_spectrum,
    band_power,
    welch_psd,
    window_info,
)

FS = 2048.0
N = 1 << 16
SEG = 2048  # 1 Hz bins


@pytest.mark.parametrize("win", sorted(WINDOWS))
def test_sine_amplitude_and_power_for_every_window(win):
    amp, f0 = 1.7, 100.0  # on a bin
    t = np.arange(N) / FS
    x = amp * np.sin(2 * np.pi * f0 * t + 0.4)
    freqs, a = averaged_amplitude_spectrum(x, FS, win, segment_length=SEG)
    assert a[np.argmin(np.abs(freqs - f0))] == pytest.approx(amp, rel=1e-9)
    f, p = welch_psd(x, FS, win, segment_length=SEG)
    # Parseval: the tone's power A^2/2 integrates over its main lobe (±6 bins covers all windows)
    assert band_power(f, p, (f0 - 6, f0 + 6)) == pytest.approx(amp**2 / 2, rel=1e-6)
    assert band_power(f, p, (0, FS / 2)) == pytest.approx(amp**2 / 2, rel=1e-6)


@pytest.mark.parametrize("win", sorted(WINDOWS))
def test_white_noise_level_for_every_window(win):
    sigma = 0.5
    x = np.random.default_rng(5).normal(scale=sigma, size=N)
    f, p = welch_psd(x, FS, win, segment_length=SEG)
    # one-sided white PSD 2 sigma^2 / fs, integral = variance (Parseval)
    assert np.mean(p[1:-1]) == pytest.approx(2 * sigma**2 / FS, rel=0.02)
    assert band_power(f, p, (0, FS / 2)) == pytest.approx(np.var(x), rel=0.02)
    # amplitude scaling of noise: mean A^2 = 4 sigma^2 ENBW_bins / N_seg
    info = window_info(win, SEG)
    _, a = averaged_amplitude_spectrum(x, FS, win, segment_length=SEG)
    assert np.mean(a[1:-1] ** 2) == pytest.approx(4 * sigma**2 * info.enbw_bins / SEG, rel=0.02)


def test_window_info_closed_forms():
    n = 4096
    assert window_info("rect", n).enbw_bins == pytest.approx(1.0)
    assert window_info("hann", n).enbw_bins == pytest.approx(1.5)  # 3/8 * n / (n/2)^2 * n
    assert window_info("hann", n).coherent_gain == pytest.approx(0.5)
    assert window_info("hann", n).enbw_hz(8192.0) == pytest.approx(3.0)
    assert window_info("flattop", n).enbw_bins == pytest.approx(3.77, abs=0.01)


def test_bad_arguments():
    with pytest.raises(RecordError, match="segment_length"):
        welch_psd(np.ones(10), 10.0, segment_length=20)
    with pytest.raises(RecordError, match="overlap"):
        welch_psd(np.ones(10), 10.0, overlap=1.0)


def test_cli_view_psd_rms_obeys_parseval(tmp_path, capsys):
    readers = pytest.importorskip("dtwin.io.readers", reason="record readers not available yet")
    import json

    from dtwin.cli import main
    from dtwin.io import Record

    t = np.arange(1 << 14) / FS
    x = 2.0 * np.sin(2 * np.pi * 300.0 * t) + np.random.default_rng(9).normal(scale=0.5, size=t.size)
    path = tmp_path / "psd.dtwin.h5"
    readers.write_record(Record(x[None, :], FS, ("acc",), ("m/s^2",)), path)
    main(["view", str(path), "--kind", "psd", "--band", "290", "310", "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert rep["rms_total"] == pytest.approx(np.sqrt(2.0**2 / 2 + 0.5**2), rel=0.02)
    assert rep["rms_band"] == pytest.approx(np.sqrt(2.0), rel=0.02)  # the tone, A / sqrt 2
