"""Real cepstrum: a family of sidebands spaced Δf shows as rahmonics at quefrencies k / Δf.

``c(q) = IFFT( log |FFT(w x)| )`` (real part), quefrency q in seconds. A spectrum with a
periodic pattern of spacing Δf (the fm ± n·fc family of a planetary gearbox, harmonics of a
shaft) has a log-spectrum periodic in f, which the inverse transform concentrates at
``q = 1/Δf`` and its multiples (rahmonics). The logarithm takes ``max(|X|, floor)`` so empty bins
give a finite value (docs/references.md §7). Reference: Randall, "Vibration-based condition
monitoring" (2011), ch. 3; Bogert, Healy & Tukey (1963).
"""

from __future__ import annotations

import numpy as np

from ..errors import RecordError
from .spectrum import as_signal, get_window

__all__ = ["rahmonics", "real_cepstrum"]


def real_cepstrum(
    x, *, sample_rate: float | None = None, channel: str | int = 0, window: str = "hann",
    floor: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Real cepstrum of a signal (numpy array with `sample_rate` Hz, or a Record's `channel`).

    `floor` (unit of the spectrum ``|FFT(w x)|``) defaults to ``1e-12 × max``.
    **Returns:** ``(quefrency, cepstrum)``: quefrencies 0 … N/2 / fs (s) and the dimensionless
    cepstrum (natural log).
    """
    sig, fs = as_signal(x, sample_rate, channel)
    mag = np.abs(np.fft.fft(sig * get_window(window, sig.size)))
    fl = 1e-12 * mag.max() if floor is None else float(floor)
    if not fl > 0:
        raise RecordError("the signal is all zeros (or floor <= 0): its cepstrum is undefined")
    c = np.fft.ifft(np.log(np.maximum(mag, fl))).real
    half = sig.size // 2 + 1
    return np.arange(half) / fs, c[:half]


def rahmonics(
    quefrency: np.ndarray, cepstrum: np.ndarray, spacing_hz: float, n: int = 5
) -> np.ndarray:
    """Cepstrum levels at the first `n` rahmonics ``k / spacing_hz`` (s), max within ±1 bin."""
    dq = quefrency[1] - quefrency[0]
    out = []
    for k in range(1, n + 1):
        i = int(round(k / spacing_hz / dq))
        if i >= quefrency.size - 1:
            break
        out.append(float(np.max(cepstrum[max(i - 1, 0) : i + 2])))
    return np.asarray(out)
