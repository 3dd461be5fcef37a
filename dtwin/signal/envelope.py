"""Envelope analysis: band-pass, Hilbert envelope, envelope spectrum, fast kurtogram.

A local fault (a cracked or missing tooth, a bearing defect) strikes once per revolution of the
faulty part and rings a structural resonance; the resonance band carries the impulses, and the
envelope of that band repeats at the fault frequency. So: band-pass around the resonance
(:func:`bandpass`, Butterworth, zero phase), take the Hilbert envelope (:func:`envelope`) and its
spectrum (:func:`envelope_spectrum`). The band is chosen by spectral kurtosis
(:func:`fast_kurtogram`, Antoni 2007, "Fast computation of the kurtogram for the detection of
transient faults", MSSP 21:108): the band in which the complex envelope is most impulsive.

Kurtogram bands follow Antoni's 1/3-binary tree: level ``L = log2(n_bands)`` with
``n_bands = 1, 2, 3, 4, 6, 8, 12, 16, …`` bands of equal width ``fs / (2 n_bands)`` tiling
0 … fs/2 (levels 0, 1, 1.6, 2, 2.6, 3, …). :func:`fast_kurtogram` computes them with Antoni's
decimated filter bank (Antoni 2007, Sec. 4): every node of the tree is the complex envelope of
its band, sampled at twice the band's width; a node splits into its lower and upper halves by two
quasi-analytic FIR filters (one real low-pass prototype, cut-off at a quarter of the node's band,
shifted by ∓ an eighth of the node's rate) and a decimation by 2, and the 1/3 rows come from
splitting each node into thirds by three such filters and a decimation by 3. Every row of the
tree then holds N samples in all, so a row costs ``O(N)`` (a fixed number of taps per sample)
and the whole kurtogram, with its ``L ≈ log2 N - 7`` levels, ``O(N log N)``; the filters run
over all nodes of a row at once (``scipy.signal.upfirdn`` along the rows of one array).

Each node's signal is kept centred: its band occupies ``[-r/4, r/4)`` of its rate ``r``, so the
halves are centred on ``∓r/8`` (filters ``p(t) e^{∓iπt/4}`` = ``a ∓ i b`` with the real
``a = p cos(πt/4)``, ``b = p sin(πt/4)``: two real filters per split) and, after decimation,
shifted back to the centre (times ``i^n`` or ``(-i)^n``). The root is the real record shifted by
``(-i)^n``: its positive frequencies land in ``[-fs/4, fs/4)``, its negative ones in the
filters' stop band. The level-0 row is the analytic signal of the whole record (one FFT).

The filters are linear (a causal FIR): the first samples of each node (the filters' run-in, at
most the taps of one filter at the node's rate) are left out of its kurtosis. The bands are the
filters' bands, not ideal ones: 6 dB down at the band edges (the prototype is a Kaiser-windowed
``scipy.signal.firwin``, 33 taps for halves, 49 for thirds, stop band below -70 dB beyond
1.4 × the half-width), so a line near an edge counts in both neighbours and the kurtosis map
differs from that of ideal (brick-wall) bands by the share of each band's power in its
transition regions.

The spectral kurtosis of a complex envelope is ``K = mean|c|^4 / mean(|c|^2)^2 - 2`` (0 for a
complex Gaussian envelope, -1 for a constant one — a pure tone —, large for impulses).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.signal

from ..errors import RecordError
from .spectrum import as_signal
from .spectrum import envelope_spectrum as _envelope_spectrum

__all__ = ["Kurtogram", "bandpass", "envelope", "envelope_spectrum", "fast_kurtogram"]


def bandpass(
    x, band: tuple[float, float], *, sample_rate: float | None = None, channel: str | int = 0,
    order: int = 4,
) -> np.ndarray:
    """Zero-phase Butterworth band-pass (scipy.signal.butter + sosfiltfilt).

    **Arguments:** `x` a signal (with `sample_rate`, Hz) or a :class:`dtwin.io.Record`
    (`channel`); `band` = (low, high) in Hz, a low edge <= 0 gives a low-pass and a high edge >=
    the Nyquist frequency a high-pass; `order` of the Butterworth design (doubled by the
    forward-backward pass). **Returns:** the filtered signal (unit of `x`).
    """
    sig, fs = as_signal(x, sample_rate, channel)
    lo, hi = float(band[0]), float(band[1])
    nyq = fs / 2
    if not lo < hi or lo >= nyq or hi <= 0:
        raise RecordError(
            f"band {band} Hz must be (low, high) with low < high overlapping 0–{nyq:g} Hz"
        )
    if lo <= 0 and hi >= nyq:
        return sig.copy()
    if lo <= 0:
        sos = scipy.signal.butter(order, hi, btype="low", fs=fs, output="sos")
    elif hi >= nyq:
        sos = scipy.signal.butter(order, lo, btype="high", fs=fs, output="sos")
    else:
        sos = scipy.signal.butter(order, [lo, hi], btype="band", fs=fs, output="sos")
    return scipy.signal.sosfiltfilt(sos, sig)


def envelope(
    x, band: tuple[float, float] | None = None, *, sample_rate: float | None = None,
    channel: str | int = 0, order: int = 4,
) -> np.ndarray:
    """Hilbert envelope ``|y + i H[y]|`` of the signal band-passed to `band` (Hz; None: whole)."""
    sig, fs = as_signal(x, sample_rate, channel)
    y = sig if band is None else bandpass(sig, band, sample_rate=fs, order=order)
    return np.abs(scipy.signal.hilbert(y))


def envelope_spectrum(
    x, band: tuple[float, float] | None = None, *, sample_rate: float | None = None,
    channel: str | int = 0, window: str = "hann", order: int = 4,
) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude spectrum of the envelope (mean removed) of the band-passed signal.

    **Returns:** ``(freqs, amplitude)`` in Hz and the signal's unit; a carrier amplitude-modulated
    with depth mu at f_mod reads ``mu × carrier amplitude`` at f_mod.
    """
    sig, fs = as_signal(x, sample_rate, channel)
    y = sig if band is None else bandpass(sig, band, sample_rate=fs, order=order)
    return _envelope_spectrum(y, fs, window)


@dataclasses.dataclass(frozen=True)
class Kurtogram:
    """Spectral kurtosis of every band of the 1/3-binary tree, and the band picked.

    - `levels`: level of each row, ``log2(n_bands)`` (0, 1, 1.585, 2, 2.585, …).
    - `n_bands`: bands in each row.
    - `kurtosis`: shape ``(rows, max n_bands)``; row r holds ``n_bands[r]`` values, NaN after.
    - `sample_rate`: Hz.
    - `best_level`, `best_band` (low, high in Hz), `best_kurtosis`: the maximum.
    """

    levels: np.ndarray
    n_bands: np.ndarray
    kurtosis: np.ndarray
    sample_rate: float
    best_level: float
    best_band: tuple[float, float]
    best_kurtosis: float

    @property
    def best_centre(self) -> float:
        """Centre frequency of the picked band (Hz)."""
        return 0.5 * (self.best_band[0] + self.best_band[1])

    @property
    def best_bandwidth(self) -> float:
        """Width of the picked band (Hz)."""
        return self.best_band[1] - self.best_band[0]


def _band_counts(max_level: int) -> list[int]:
    counts = [1]
    for k in range(1, max_level + 1):
        counts.append(2**k)
        if k < max_level:
            counts.append(3 * 2 ** (k - 1))  # 3, 6, 12 …: the 1/3 levels
    return sorted(set(counts))


#: Taps of the half-band prototype (splits into halves) and of the third-band one (thirds).
_TAPS_HALF, _TAPS_THIRD, _KAISER_BETA = 33, 49, 6.0


def _prototypes() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Real filters of the bank (module docstring): ``a, b`` (halves: ``a ∓ i b`` passes the
    lower / upper half of a centred node) and ``p3, c3, s3`` (thirds: ``c3 ∓ i s3`` the outer
    thirds, ``p3`` the middle one)."""
    p2 = scipy.signal.firwin(_TAPS_HALF, 0.25, window=("kaiser", _KAISER_BETA))
    t2 = np.arange(_TAPS_HALF) - (_TAPS_HALF - 1) / 2
    p3 = scipy.signal.firwin(_TAPS_THIRD, 1.0 / 6.0, window=("kaiser", _KAISER_BETA))
    t3 = np.arange(_TAPS_THIRD) - (_TAPS_THIRD - 1) / 2
    return (p2 * np.cos(np.pi * t2 / 4), p2 * np.sin(np.pi * t2 / 4), p3,
            p3 * np.cos(np.pi * t3 / 3), p3 * np.sin(np.pi * t3 / 3))


def _filter_down(taps: np.ndarray, re_im: np.ndarray, down: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Causal FIR of real `taps` along the rows of `re_im` (the real parts of the nodes stacked
    over their imaginary parts), every `down`-th output: ``(real, imag)``, ``ceil(m / down)``
    samples per node."""
    y = scipy.signal.upfirdn(taps, re_im, 1, down, axis=-1)[:, : -(-m // down)]
    half = y.shape[0] // 2
    return y[:half], y[half:]


_TURN = np.array([1.0, 1.0j, -1.0, -1.0j])  # i^n for n mod 4


#: A band whose mean power lies this far below the record's (-200 dB) holds rounding errors
#: only (float64 resolves about -300 dB): its kurtosis is NaN, not a random number.
_NO_POWER = 1e-20


def _kurtosis_rows(re: np.ndarray, im: np.ndarray, skip: int, total: float) -> np.ndarray:
    """``mean|c|^4 / mean(|c|^2)^2 - 2`` of each row, its first `skip` samples left out; NaN
    for a row whose mean power is below ``_NO_POWER × total``."""
    p = re[:, skip:] ** 2 + im[:, skip:] ** 2
    m2 = p.mean(axis=1)
    m4 = np.mean(p * p, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = m4 / (m2 * m2) - 2.0
    return np.where(m2 > _NO_POWER * total, k, np.nan)


def fast_kurtogram(
    x, *, sample_rate: float | None = None, channel: str | int = 0, max_level: int | None = None,
) -> Kurtogram:
    """Spectral kurtosis over Antoni's band tree and the band where it is largest.

    The filter bank of the module docstring: ``O(N log N)`` for N samples.

    **Arguments:** `x` a signal (with `sample_rate`, Hz) or a :class:`dtwin.io.Record`;
    `max_level`: finest level (``2**max_level`` bands); default ``floor(log2(N)) - 7`` as Antoni
    suggests, at least 1.

    **Returns:** a :class:`Kurtogram`; ``best_band`` is the band to pass to :func:`envelope`.
    """
    sig, fs = as_signal(x, sample_rate, channel)
    n = sig.size
    if n < 256:
        raise RecordError(f"a kurtogram needs at least 256 samples, got {n}")
    top = int(max_level) if max_level is not None else max(1, int(np.floor(np.log2(n))) - 7)
    if top < 1 or 2**top > n // 8:
        raise RecordError(f"max_level must lie between 1 and {int(np.log2(n // 8))}, got {max_level}")
    sig = sig - sig.mean()
    a, b, p3, c3, s3 = _prototypes()
    counts = _band_counts(top)
    analytic = scipy.signal.hilbert(sig)[None]
    total = float(np.mean(analytic.real**2 + analytic.imag**2))
    if not total > 0:
        raise RecordError("a kurtogram needs a signal that varies; this one is constant")
    rows: dict[int, np.ndarray] = {1: _kurtosis_rows(analytic.real, analytic.imag, 0, total)}
    del analytic
    # the root: positive frequencies shifted to [-fs/4, fs/4) (module docstring)
    node = (sig * _TURN[(-np.arange(n)) % 4])[None, :]
    for k in range(top):
        m = node.shape[1]
        stacked = np.concatenate([node.real, node.imag])
        if 3 * 2**k in counts:  # thirds of every node: the row of 3 * 2**k bands
            mr, mi = _filter_down(p3, stacked, 3, m)
            cr, ci = _filter_down(c3, stacked, 3, m)
            sr, si = _filter_down(s3, stacked, 3, m)
            skip = min(-(-(_TAPS_THIRD + _TAPS_HALF) // 3), mr.shape[1] // 2)
            k_lo = _kurtosis_rows(cr + si, ci - sr, skip, total)  # (c3 - i s3): the lower third
            k_mid = _kurtosis_rows(mr, mi, skip, total)
            k_hi = _kurtosis_rows(cr - si, ci + sr, skip, total)
            rows[3 * 2**k] = np.stack([k_lo, k_mid, k_hi], axis=1).ravel()
        ar, ai = _filter_down(a, stacked, 2, m)
        br, bi = _filter_down(b, stacked, 2, m)
        turn = _TURN[np.arange(ar.shape[1]) % 4]  # i^n: the halves back to the centre
        child = np.empty((2 * node.shape[0], ar.shape[1]), dtype=np.complex128)
        child[0::2] = ((ar + bi) + 1j * (ai - br)) * turn  # (a - i b): lower half, up by r'/4
        child[1::2] = ((ar - bi) + 1j * (ai + br)) * turn.conj()  # (a + i b): upper, down
        node = child
        rows[2 ** (k + 1)] = _kurtosis_rows(node.real, node.imag,
                                            min(_TAPS_HALF, node.shape[1] // 2), total)
    kurt = np.full((len(counts), max(counts)), np.nan)
    best = (-np.inf, 0.0, (0.0, fs / 2))
    for r, nb in enumerate(counts):
        kurt[r, :nb] = rows[nb]
        width = fs / 2 / nb
        if np.any(np.isfinite(rows[nb])):
            j = int(np.nanargmax(rows[nb]))
            if rows[nb][j] > best[0]:
                best = (float(rows[nb][j]), float(np.log2(nb)), (j * width, (j + 1) * width))
    return Kurtogram(np.log2(np.asarray(counts, dtype=np.float64)), np.asarray(counts), kurt,
                     fs, best[1], best[2], best[0])
