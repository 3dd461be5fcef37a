"""Amplitude spectra, envelope spectra, noise floor, peaks and their gear-frequency labels.

The core transforms (:func:`get_window`, :func:`amplitude_spectrum`, :func:`analytic_signal`,
:func:`envelope_spectrum`, :func:`to_db`) work on numpy arrays *and* on JAX arrays: with JAX
input they use ``jnp.fft`` and are jittable and differentiable, so the identification fits use
the very same spectra as the figures. Frequencies are returned as numpy arrays (they depend only
on the static length and sample rate).

Scaling (one-sided amplitude spectrum, amplitude-corrected for tones)::

    X_k = sum_n w_n x_n exp(-2 pi i k n / N),     A_k = 2 |X_k| / sum_n w_n   (0 < k < N/2)
    A_0 = |X_0| / sum_n w_n,  A_{N/2} = |X_{N/2}| / sum_n w_n

so a sine ``A sin(2 pi f t)`` on a bin gives a peak ``A`` for every window (the window's coherent
gain is divided out). Off a bin the peak is lower by the window's scalloping loss (up to 36 % for
``rect``, 15 % for ``hann``, < 0.2 % for ``flattop``: use ``flattop`` to read amplitudes).
Noise is *not* amplitude-correct in this scaling; use :mod:`dtwin.signal.psd` for noise levels.

The noise floor (docs/references.md §7) is a running median of the linear amplitude over a window of
bins, estimated before any logarithm and clamped to a positive minimum, so empty bins never give
``log 0``. Peaks are local maxima standing a threshold (dB) above that floor.

Peak labels: every peak frequency is matched to the combinations ::

    f = m f_mesh + a f_carrier + b f_sun_fault / N + c f_planet_fault

with ``0 <= m <= 4``, ``|a| <= 8``, ``|b| <= 3``, ``|c| <= 3`` (:class:`dtwin.model.kinematics.OrderBounds`:
`mesh`, `carrier`, `fault`) lying within
the frequency resolution of the peak. Candidates are ranked by parsimony: first by the number of
frequency families used (nonzero m, a, b, c), then by the total order ``m + |a| + |b| + |c|``,
then by the frequency error; all candidates sharing the best (families, order) are reported
(ties). Without the family count a high carrier sideband such as fm − 7fc would lose to
accidental four-family combinations like fm − 2fs/3 + fp − 2fc (order 6). Labels are written like
the paper's figures ("fm − 7fc", "fm + fs/3 + fc"; ``fs`` = f_sun_fault, ``fp`` = f_planet_fault)
by :func:`dtwin.model.kinematics.combination_text`. The frequencies are a
:class:`dtwin.model.kinematics.Kinematics` (``FrequencyBasis`` is its name here).
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..errors import RecordError
from ..io.record import Record
from ..model.kinematics import Kinematics, OrderBounds, combination_text
from .indicators import TimeStats, time_stats

__all__ = [
    "WINDOWS",
    "FrequencyBasis",
    "Label",
    "LabelBounds",
    "LabelledPeak",
    "Peak",
    "TimeStats",
    "amplitude_spectrum",
    "analytic_signal",
    "as_signal",
    "envelope_spectrum",
    "find_peaks",
    "label_frequency",
    "label_peaks",
    "level_at",
    "noise_floor",
    "time_stats",
    "to_db",
    "get_window",
    "zoom",
]

#: Windows offered everywhere in dtwin, mapped to their scipy.signal names.
WINDOWS: dict[str, str | tuple] = {
    "rect": "boxcar",
    "hann": "hann",
    "hamming": "hamming",
    "blackman": "blackman",
    "blackmanharris": "blackmanharris",
    "flattop": "flattop",
}


def _xp(x):
    return jnp if isinstance(x, jax.Array) else np


def _as_array(x):
    if isinstance(x, jax.Array):
        return x
    return np.asarray(x, dtype=np.float64)


def as_signal(
    x, sample_rate: float | None = None, channel: str | int = 0
) -> tuple[np.ndarray, float]:
    """One channel as a float64 numpy array and its sampling rate (Hz).

    `x` is a :class:`dtwin.io.Record` (then `channel` picks the row and the record's rate is used;
    a `sample_rate` that disagrees raises) or a 1-D array (then `sample_rate` is required).
    """
    if isinstance(x, Record):
        if sample_rate is not None and float(sample_rate) != float(x.sample_rate):
            raise RecordError(
                f"sample_rate {sample_rate} Hz disagrees with the record's {x.sample_rate} Hz; "
                "leave sample_rate out when passing a Record"
            )
        return np.asarray(x.channel(channel), dtype=np.float64), _check_rate(x.sample_rate)
    if sample_rate is None:
        raise RecordError("pass sample_rate (Hz) with a plain array, or pass a dtwin.io.Record")
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim != 1:
        raise RecordError(f"expected one channel (1-D array), got shape {arr.shape}")
    return arr, _check_rate(sample_rate)


def get_window(name: str, n: int) -> np.ndarray:
    """The periodic (DFT-even) window `name` of length `n` as float64 numpy array.

    `name` is one of :data:`WINDOWS` (``rect``, ``hann``, ``hamming``, ``blackman``,
    ``blackmanharris``, ``flattop``); scipy.signal.get_window computes it.
    """
    if name not in WINDOWS:
        raise RecordError(f"unknown window {name!r}; choose one of {sorted(WINDOWS)}")
    if n < 2:
        raise RecordError(f"a spectrum needs at least 2 samples, got {n}")
    import scipy.signal  # deferred: scipy.signal takes seconds to import; `import dtwin` stays light

    return np.asarray(scipy.signal.get_window(WINDOWS[name], n, fftbins=True), dtype=np.float64)


def _check_rate(sample_rate: float) -> float:
    fs = float(sample_rate)
    if not np.isfinite(fs) or fs <= 0:
        raise RecordError(f"sample_rate must be a positive number of Hz, got {sample_rate!r}")
    return fs


def amplitude_spectrum(
    x: Float[Array, "... time"],
    sample_rate: float,
    window: str = "hann",
    *,
    remove_mean: bool = False,
) -> tuple[np.ndarray, Float[Array, "... freq"]]:
    """One-sided, amplitude-corrected spectrum ``A_k = 2 |X_k| / sum(w)`` (module docstring).

    **Arguments:**

    - `x`: signal(s), time on the last axis (numpy or JAX; JAX input is differentiable).
    - `sample_rate`: sampling rate (Hz).
    - `window`: one of :data:`WINDOWS`.
    - `remove_mean`: subtract the mean before windowing (removes the DC line and its leakage).

    **Returns:** ``(freqs, amplitude)``: bin frequencies (Hz, numpy, spacing ``fs / N``) and peak
    amplitudes in the unit of `x` (numpy in, numpy out; JAX in, JAX out).
    """
    fs = _check_rate(sample_rate)
    x = _as_array(x)
    xp = _xp(x)
    n = x.shape[-1]
    w = get_window(window, n)
    if remove_mean:
        x = x - xp.mean(x, axis=-1, keepdims=True)
    spec = xp.fft.rfft(x * xp.asarray(w), axis=-1)
    scale = np.full(n // 2 + 1, 2.0 / w.sum())
    scale[0] = 1.0 / w.sum()
    if n % 2 == 0:
        scale[-1] = 1.0 / w.sum()
    return np.fft.rfftfreq(n, 1.0 / fs), xp.abs(spec) * xp.asarray(scale)


def analytic_signal(x: Float[Array, "... time"]) -> Array:
    """Analytic signal ``x + i H[x]`` by the FFT (same as ``scipy.signal.hilbert``).

    ``Z_k = X_k`` for k = 0 and N/2, ``2 X_k`` for 0 < k < N/2 and 0 for negative frequencies.
    numpy input uses scipy.signal.hilbert; JAX input the same formula with ``jnp.fft``.
    """
    x = _as_array(x)
    if not isinstance(x, jax.Array):
        import scipy.signal  # deferred: a heavy import that `import dtwin` does not need

        return scipy.signal.hilbert(x, axis=-1)
    n = x.shape[-1]
    h = np.zeros(n)
    h[0] = 1.0
    if n % 2 == 0:
        h[n // 2] = 1.0
        h[1 : n // 2] = 2.0
    else:
        h[1 : (n + 1) // 2] = 2.0
    return jnp.fft.ifft(jnp.fft.fft(x, axis=-1) * jnp.asarray(h, dtype=jnp.complex128), axis=-1)


def envelope_spectrum(
    x: Float[Array, "... time"], sample_rate: float, window: str = "hann"
) -> tuple[np.ndarray, Float[Array, "... freq"]]:
    """Amplitude spectrum of the Hilbert envelope ``|x + i H[x]|`` with its mean removed.

    A carrier ``(1 + mu cos 2 pi f_mod t) cos 2 pi f_c t`` gives a line of height ``mu`` at
    ``f_mod`` (for ``f_c`` well above ``f_mod``). Band-pass first (:mod:`dtwin.signal.envelope`) when the
    modulated carrier is not the only content.

    **Returns:** ``(freqs, amplitude)`` as :func:`amplitude_spectrum`.
    """
    x = _as_array(x)
    xp = _xp(x)
    env = xp.abs(analytic_signal(x))
    return amplitude_spectrum(env, sample_rate, window, remove_mean=True)


def zoom(
    freqs: np.ndarray, spec: Float[Array, "... freq"], band: tuple[float, float]
) -> tuple[np.ndarray, Float[Array, "... freq"]]:
    """The bins with ``band[0] <= f <= band[1]`` (Hz) of a spectrum: ``(freqs, spec)``."""
    lo, hi = float(band[0]), float(band[1])
    if not lo < hi:
        raise RecordError(f"band must be (low, high) with low < high in Hz, got {band}")
    freqs = np.asarray(freqs)
    sel = np.flatnonzero((freqs >= lo) & (freqs <= hi))
    if sel.size == 0:
        raise RecordError(
            f"band {lo}–{hi} Hz holds no spectral bin (bins span {freqs[0]}–{freqs[-1]} Hz); "
            "choose a band inside the spectrum"
        )
    return freqs[sel], spec[..., sel[0] : sel[-1] + 1]


def noise_floor(
    spec: np.ndarray, width_bins: int = 31, *, min_fraction: float = 1e-12
) -> np.ndarray:
    """Robust noise floor: running median of the linear amplitude over `width_bins` bins.

    Estimated before any logarithm (docs/references.md §7) and clamped below at
    ``min_fraction * max(spec)`` (and the smallest positive float), so it is never zero. For white
    Gaussian noise of standard deviation sigma, the amplitude of a bin is Rayleigh distributed and
    the median floor is ``2 sigma sqrt(ln 2 * sum w^2) / sum w`` (sigma sqrt(4 ln 2 / N) for
    ``rect``).

    **Arguments:**

    - `spec`: a linear amplitude (or power) spectrum, last axis frequency.
    - `width_bins`: odd number of bins of the running window (wider than a peak's main lobe).
    - `min_fraction`: lower clamp relative to the spectrum's maximum.

    **Returns:** the floor, same shape and unit as `spec`.
    """
    spec = np.asarray(spec, dtype=np.float64)
    width = int(width_bins)
    if width < 3:
        raise RecordError(f"noise-floor window must span at least 3 bins, got {width_bins}")
    width += 1 - width % 2
    import scipy.ndimage  # deferred: a heavy import that `import dtwin` does not need

    # one row at a time: SciPy's 1-D rank filter is ~9x faster than its n-D one on (.., 1, w)
    shape = (math.prod(spec.shape[:-1]), spec.shape[-1]) if spec.ndim else (1, 1)
    rows = spec.reshape(shape)
    floor = np.empty_like(rows)
    for row, out in zip(rows, floor, strict=True):
        scipy.ndimage.median_filter(row, size=width, mode="nearest", output=out)
    floor = floor.reshape(spec.shape)
    lowest = max(float(np.max(spec, initial=0.0)) * min_fraction, np.finfo(np.float64).tiny)
    return np.maximum(floor, lowest)


def to_db(
    spec: Float[Array, "..."], ref: float = 1.0, floor: float | Float[Array, "..."] | None = None,
    *, power: bool = False,
) -> Float[Array, "..."]:
    """Level in dB re `ref`: ``20 log10(max(spec, floor) / ref)`` (``10 log10`` if `power`).

    `floor` (same unit as `spec`) keeps empty bins finite; by default it is
    ``1e-12 * max(spec)`` (-240 dB re the maximum) or the smallest positive float.
    """
    spec = _as_array(spec)
    xp = _xp(spec)
    if floor is None:
        floor = xp.maximum(xp.max(spec) * 1e-12, np.finfo(np.float64).tiny)
    k = 10.0 if power else 20.0
    return k * xp.log10(xp.maximum(spec, floor) / ref)


def level_at(freqs: np.ndarray, spec: np.ndarray, f: float) -> float:
    """Largest amplitude within ±1 bin of frequency `f` (Hz): the level of a line at `f`."""
    freqs = np.asarray(freqs)
    if not freqs[0] <= f <= freqs[-1]:
        raise RecordError(f"{f} Hz lies outside the spectrum ({freqs[0]}–{freqs[-1]} Hz)")
    df = freqs[1] - freqs[0]
    k = int(round((f - freqs[0]) / df))
    lo, hi = max(k - 1, 0), min(k + 2, len(freqs))
    return float(np.max(np.asarray(spec)[lo:hi]))


@dataclasses.dataclass(frozen=True)
class Peak:
    """A spectral peak: bin `index`, `frequency` (Hz), `amplitude` (signal unit), the noise
    `floor` there (signal unit) and `above_floor_db` = 20 log10(amplitude / floor)."""

    index: int
    frequency: float
    amplitude: float
    floor: float
    above_floor_db: float


def find_peaks(
    freqs: np.ndarray,
    spec: np.ndarray,
    *,
    threshold_db: float = 10.0,
    min_spacing_hz: float | None = None,
    band: tuple[float, float] | None = None,
    floor: np.ndarray | None = None,
    width_bins: int = 31,
    max_peaks: int | None = None,
) -> list[Peak]:
    """Local maxima of an amplitude spectrum at least `threshold_db` above the noise floor.

    **Arguments:**

    - `freqs`, `spec`: a one-sided amplitude spectrum (Hz, signal unit).
    - `threshold_db`: minimum height above the floor (dB, amplitude ratio).
    - `min_spacing_hz`: minimum distance between peaks (Hz; default one bin). Of two peaks closer
      than this the higher is kept (scipy.signal.find_peaks ``distance``).
    - `band`: only peaks with ``band[0] <= f <= band[1]`` (Hz) are returned (the floor is still
      estimated on the whole spectrum, so band edges do not bias it).
    - `floor`: a precomputed noise floor; default :func:`noise_floor` with `width_bins`.
    - `max_peaks`: keep only the highest this many (by height above the floor).

    **Returns:** the peaks, sorted by frequency.
    """
    freqs = np.asarray(freqs, dtype=np.float64)
    spec = np.asarray(spec, dtype=np.float64)
    if spec.ndim != 1 or spec.shape != freqs.shape:
        raise RecordError("find_peaks needs one spectrum (1-D) and its frequencies, same length")
    if floor is None:
        floor = noise_floor(spec, width_bins)
    df = freqs[1] - freqs[0]
    distance = 1 if min_spacing_hz is None else max(1, int(round(min_spacing_hz / df)))
    height = floor * 10.0 ** (threshold_db / 20.0)
    import scipy.signal  # deferred: a heavy import that `import dtwin` does not need

    idx, _ = scipy.signal.find_peaks(spec, height=height, distance=distance)
    if band is not None:
        idx = idx[(freqs[idx] >= band[0]) & (freqs[idx] <= band[1])]
    peaks = [
        Peak(int(i), float(freqs[i]), float(spec[i]), float(floor[i]),
             float(20 * np.log10(spec[i] / floor[i])))
        for i in idx
    ]
    if max_peaks is not None and len(peaks) > max_peaks:
        peaks = sorted(peaks, key=lambda p: -p.above_floor_db)[:max_peaks]
        peaks.sort(key=lambda p: p.frequency)
    return peaks


#: The gear frequencies peaks are labelled with: a :class:`dtwin.model.kinematics.Kinematics`
#: (``FrequencyBasis(f_mesh, f_carrier, f_sun_fault, f_planet_fault, n_planets)``; fault
#: frequencies left None are not used; ``f_sun_fault`` enters divided by `n_planets`).
FrequencyBasis = Kinematics
#: Order bounds of the label search (``0 <= m <= mesh``, ``|a| <= carrier``, ``|b|, |c| <=
#: fault``): :class:`dtwin.model.kinematics.OrderBounds`.
LabelBounds = OrderBounds


@dataclasses.dataclass(frozen=True)
class Label:
    """A combination ``m fm + a fc + b fs/N + c fp`` at `frequency` (Hz), `error` = peak minus
    combination (Hz), `order` = m + |a| + |b| + |c|, and its `text` ("fm + fs/3 − fc")."""

    m: int
    a: int
    b: int
    c: int
    frequency: float
    error: float
    order: int
    text: str

    @property
    def families(self) -> int:
        """Number of frequency families used (nonzero coefficients among m, a, b, c)."""
        return sum(v != 0 for v in (self.m, self.a, self.b, self.c))

    @property
    def rank(self) -> tuple[int, int]:
        """Ranking key (families, total order); lower is more parsimonious."""
        return (self.families, self.order)


def _label_text(m: int, a: int, b: int, c: int, n_planets: int) -> str:
    return combination_text((("fm", m), (f"fs/{n_planets}", b), ("fp", c), ("fc", a)))


def _combinations(basis: Kinematics, bounds: OrderBounds):
    ms = range(0, bounds.mesh + 1)
    as_ = range(-bounds.carrier, bounds.carrier + 1)
    bs = range(-bounds.fault, bounds.fault + 1) if basis.f_sun_fault is not None else (0,)
    cs = range(-bounds.fault, bounds.fault + 1) if basis.f_planet_fault is not None else (0,)
    combos = np.array(list(itertools.product(ms, as_, bs, cs)), dtype=np.int64)
    fs_n = (basis.f_sun_fault or 0.0) / basis.n_planets
    fp = basis.f_planet_fault or 0.0
    freq = (combos[:, 0] * basis.f_mesh + combos[:, 1] * basis.f_carrier
            + combos[:, 2] * fs_n + combos[:, 3] * fp)
    order = np.abs(combos).sum(axis=1)
    keep = (order > 0) & (freq > 0)
    return combos[keep], freq[keep], order[keep]


def label_frequency(
    f: float,
    basis: FrequencyBasis,
    tolerance: float,
    bounds: LabelBounds = LabelBounds(),
) -> list[Label]:
    """All combinations within `tolerance` (Hz) of `f`, best first: fewest families (nonzero
    coefficients), then lowest total order, then smallest |error| (module docstring)."""
    combos, freq, order = _combinations(basis, bounds)
    err = f - freq
    hit = np.flatnonzero(np.abs(err) <= tolerance)
    families = np.count_nonzero(combos, axis=1)
    ranked = sorted(hit, key=lambda i: (families[i], order[i], abs(err[i])))
    return [
        Label(int(combos[i, 0]), int(combos[i, 1]), int(combos[i, 2]), int(combos[i, 3]),
              float(freq[i]), float(err[i]), int(order[i]),
              _label_text(*(int(v) for v in combos[i]), basis.n_planets))
        for i in ranked
    ]


@dataclasses.dataclass(frozen=True)
class LabelledPeak:
    """A peak numbered `number` (1, 2, … by frequency), its best `labels` (all candidates of the
    best rank: ties) and the further, lower-ranked `alternatives` within the tolerance, best
    first. On the bench gearbox, where fs/3 = 4 fc exactly, a line at fm + 5fc carries the label
    "fm + 5fc" and the alternative "fm + fs/3 + fc": both explain it."""

    number: int
    peak: Peak
    labels: tuple[Label, ...]
    alternatives: tuple[Label, ...] = ()

    @property
    def n_alternatives(self) -> int:
        return len(self.alternatives)

    @property
    def text(self) -> str:
        """The label(s): "fm − 7fc", ties joined by " | ", "?" when nothing matched."""
        return " | ".join(lab.text for lab in self.labels) if self.labels else "?"


def label_peaks(
    peaks: list[Peak],
    basis: FrequencyBasis,
    resolution: float,
    bounds: LabelBounds = LabelBounds(),
) -> list[LabelledPeak]:
    """Label every peak with its best-ranked combinations within `resolution` (Hz).

    `resolution` is the frequency resolution of the spectrum (its bin spacing ``fs / N``, or more
    for a window with a wide main lobe); a peak's bin lies within half a bin of a true line, so a
    tolerance of one bin also absorbs small errors in the gear frequencies. Peaks are numbered
    1, 2, … in frequency order, as in the paper's figures.
    """
    if resolution <= 0:
        raise RecordError(f"label resolution must be positive (Hz), got {resolution}")
    out = []
    for k, p in enumerate(sorted(peaks, key=lambda p: p.frequency), start=1):
        cands = label_frequency(p.frequency, basis, resolution, bounds)
        best = tuple(c for c in cands if c.rank == cands[0].rank)
        rest = tuple(c for c in cands if c.rank != cands[0].rank)
        out.append(LabelledPeak(k, p, best, rest))
    return out
