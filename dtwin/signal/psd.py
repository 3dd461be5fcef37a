"""Welch power spectral density and averaged amplitude spectra (built on scipy.signal.welch).

Scaling, one-sided, for a segment of N samples with window ``w`` (periodic, :data:`WINDOWS`):

- **PSD** (:func:`welch_psd`, unit²/Hz): ``P_k = c_k |X_k|^2 / (fs * sum w^2)`` with ``c_k = 2``
  except at DC and Nyquist (1). Dividing by ``sum w^2`` is the *ENBW correction*: white noise of
  variance sigma² gives ``P = 2 sigma^2 / fs`` in every window, and by Parseval
  ``sum_k P_k * df = variance`` (df = fs/N). Use it for noise and for the power of a band
  (:func:`band_power`): a sine of amplitude A integrates to ``A^2 / 2`` over its main lobe.
- **Averaged amplitude spectrum** (:func:`averaged_amplitude_spectrum`, signal unit):
  ``A_k = a_k sqrt(mean_seg |X_k|^2) / sum w`` with ``a_k = 2`` except at DC and Nyquist (1),
  the segment powers averaged (RMS averaging) *before* the square root; dividing by ``sum w`` is the *amplitude (coherent-gain) correction*: a
  sine of amplitude A on a bin reads A for every window. Noise in this scaling depends on the
  window's ENBW (``sigma * sqrt(2 * ENBW_bins / N)``), which is why the PSD exists.

Segments overlap by `overlap` (fraction, default 0.5) and each is detrended (`detrend`, default
the mean) before windowing. :func:`window_info` gives the coherent gain and the ENBW of a window.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.signal

from ..errors import RecordError
from .spectrum import WINDOWS, get_window

__all__ = [
    "WINDOWS",
    "WindowInfo",
    "averaged_amplitude_spectrum",
    "band_power",
    "welch_psd",
    "window_info",
]


@dataclasses.dataclass(frozen=True)
class WindowInfo:
    """Corrections of a window of `n` samples.

    - `coherent_gain`: ``sum w / n`` (a tone's amplitude is multiplied by it).
    - `enbw_bins`: equivalent noise bandwidth ``n sum w^2 / (sum w)^2`` in bins (rect 1, hann 1.5,
      flattop about 3.77); ``enbw_hz(fs) = enbw_bins * fs / n``.
    """

    name: str
    n: int
    coherent_gain: float
    enbw_bins: float

    def enbw_hz(self, sample_rate: float) -> float:
        """Equivalent noise bandwidth in Hz at `sample_rate` (Hz)."""
        return self.enbw_bins * float(sample_rate) / self.n


def window_info(name: str, n: int) -> WindowInfo:
    """Coherent gain and equivalent noise bandwidth of the window `name` of length `n`."""
    w = get_window(name, n)
    return WindowInfo(name, n, float(w.sum() / n), float(n * np.sum(w * w) / w.sum() ** 2))


def _segments(n: int, segment_length: int | None, overlap: float) -> tuple[int, int]:
    nperseg = max(n // 4, 2) if segment_length is None else int(segment_length)
    if not 2 <= nperseg <= n:
        raise RecordError(
            f"segment_length {segment_length} must lie between 2 and the record length {n} samples"
        )
    if not 0.0 <= overlap < 1.0:
        raise RecordError(f"overlap must be a fraction in [0, 1), got {overlap}")
    return nperseg, int(round(overlap * nperseg))


def welch_psd(
    x: np.ndarray,
    sample_rate: float,
    window: str = "hann",
    *,
    segment_length: int | None = None,
    overlap: float = 0.5,
    detrend: str | bool = "constant",
) -> tuple[np.ndarray, np.ndarray]:
    """Welch PSD, one-sided, ENBW-corrected (module docstring).

    **Arguments:**

    - `x`: signal(s), time on the last axis.
    - `sample_rate`: sampling rate (Hz).
    - `window`: one of :data:`WINDOWS`.
    - `segment_length`: samples per segment (default a quarter of the record); the resolution is
      ``sample_rate / segment_length``.
    - `overlap`: overlap of consecutive segments (fraction).
    - `detrend`: ``"constant"`` (mean), ``"linear"`` or False, per segment.

    **Returns:** ``(freqs, psd)`` in Hz and unit²/Hz.
    """
    x = np.asarray(x, dtype=np.float64)
    nperseg, noverlap = _segments(x.shape[-1], segment_length, overlap)
    return scipy.signal.welch(
        x, fs=float(sample_rate), window=get_window(window, nperseg), nperseg=nperseg,
        noverlap=noverlap, detrend=detrend, scaling="density", return_onesided=True, axis=-1,
    )


def averaged_amplitude_spectrum(
    x: np.ndarray,
    sample_rate: float,
    window: str = "hann",
    *,
    segment_length: int | None = None,
    overlap: float = 0.5,
    detrend: str | bool = "constant",
) -> tuple[np.ndarray, np.ndarray]:
    """Averaged (RMS over segments), amplitude-corrected one-sided spectrum: a sine of amplitude A
    on a bin reads A for every window (module docstring). Arguments as :func:`welch_psd`.

    **Returns:** ``(freqs, amplitude)`` in Hz and the unit of `x`.
    """
    x = np.asarray(x, dtype=np.float64)
    nperseg, noverlap = _segments(x.shape[-1], segment_length, overlap)
    freqs, power = scipy.signal.welch(
        x, fs=float(sample_rate), window=get_window(window, nperseg), nperseg=nperseg,
        noverlap=noverlap, detrend=detrend, scaling="spectrum", return_onesided=True, axis=-1,
    )
    # scipy's one-sided "spectrum" is the RMS² per bin, doubled except at DC and Nyquist.
    factor = np.full(freqs.shape, 2.0)
    factor[0] = 1.0
    if nperseg % 2 == 0:
        factor[-1] = 1.0
    return freqs, np.sqrt(power * factor)


def band_power(freqs: np.ndarray, psd: np.ndarray, band: tuple[float, float]) -> np.ndarray:
    """Power in ``band[0] <= f <= band[1]`` (Hz): ``sum_k P_k df`` (unit²; Parseval over all bins
    gives the variance). Its square root is the band's RMS."""
    freqs = np.asarray(freqs)
    sel = (freqs >= band[0]) & (freqs <= band[1])
    if not sel.any():
        raise RecordError(f"band {band} Hz holds no bin of the PSD ({freqs[0]}–{freqs[-1]} Hz)")
    return np.sum(np.asarray(psd)[..., sel], axis=-1) * (freqs[1] - freqs[0])
