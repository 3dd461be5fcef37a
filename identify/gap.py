"""The gap between a measured record and the model, defined once.

**Definition.** On a segment of the record that was *not* used to fit (held-out), with
``A_meas`` and ``A_model`` the Hann amplitude spectra of the measured and the model signal (model
times its fitted gain) and ``F`` the measured noise floor (running median, 31 bins)::

    L = 20 log10(A + F)                                    (dB, floor added before the log)
    S = { bins in the band : A_meas > F·10^(T/20)  or  A_model > F·10^(T/20) }
    gap = sqrt( mean_{k in S} (L_meas,k − L_model,k)^2 )   (dB)

so a line the model lacks counts its full height over the floor and a line the model invents
counts too. Noise-only bins must not count. A Hann amplitude bin of noise alone exceeds ``r``
times the median floor with probability ``2^-(r²)`` (Rayleigh), 2e-5 at 12 dB. Over the
thousands of bins of a band that is not rare: about 0.15 false lines per 9000-bin half-record,
each worth ~14 dB in the gap. :func:`gap` therefore takes by default the **family-wise**
threshold :func:`family_threshold_db`. It is the height that noise alone reaches anywhere in
the band with probability at most ``alpha = 1 %``, found by Monte Carlo of this very estimator
(about 15 dB for 2 × 4500 bins of a band's interior; 17.1 dB for 0 … 0.45 fs of a 4 s,
5 kHz record, whose lowest bins lie where the running median is padded with the half-size
DC bin and so reads low), and never below 12 dB. Bins 0–2 (a segment's mean and its Hann
main lobe) never count. Discovery reports this gap too; its search decides on the gap over
12 dB bins (``threshold_db``), with a bootstrap controlling what noise does there.
Cross-validation over segments (:func:`fold_segments`): the record is cut into two halves,
parameters fitted on one half are scored on the other and vice versa;
the reported gap pools the squared differences of both folds. Adding parameters cannot shrink
this by fitting the noise of the scored half.

**The band.** The gap is taken over ``0.8 N f_c … passband × the sampling rate``. It starts at
the lowest knot of a calibrated sensor response (``LOW_BAND_START × N f_c``,
:mod:`dtwin.identify.low_band`): below it the response has no knot, and a healthy record
with equally loaded planets leaves ``f_c`` and ``2 f_c`` at the noise floor, so a calibration
gives the twin little scale there; a line a record holds there (a planet fault's own ``f_c``) is listed, not scored
(``named_bands(f_min=…)``; calibration and discovery pass it). It ends at the usable band
of the DAQ, where its anti-aliasing filter's pass band ends (the spec's ``[sensor] passband``,
:data:`PASSBAND` = 0.45 where none is given: a delta-sigma DAQ; 1/2.56 on a classic analyser).
The twin's own anti-aliasing filter passes flat to the same edge (:func:`dtwin.simulation.simulate.daq_filter`). Above it a
record holds aliases and filter-shaped lines (an independent simulator's 5 f_m = 2501.5 Hz,
above the 2500 Hz Nyquist frequency of a 5 kHz record, appears at 2498.5 Hz) that no twin of the
gearbox can be held to: calibration and discovery score the same band.

**Aliases are not scored either.** A DAQ's filter attenuates a line above Nyquist by more the
further it lies past ``(1 − passband) fs``; a mesh line just past it (``m fm + n fc`` between
fs/2 and ``(2 − ALIAS_ZONE) fs/2``, 0.6 fs) can come through its transition band and show at
``fs − f``, in the top part of the scored band (:data:`ALIAS_ZONE`, as discovery labels such
a line "alias of 11fm"). Given the sampling rate, :func:`named_bands` leaves those alias
frequencies out of every band, ± the Hann window's main lobe (two bins): a twin of the gearbox
cannot be held to an acquisition's stop band, and an alias that drifts over a healthy band
with the speed (an independent record 0.4 % faster than its calibration record: 11 fm at
5 731.8 Hz, 27 dB over the floor, where on the slower record it fell on 9 fm) is no finding.

**Named bands** (:func:`named_bands`): ``low`` (`f_min` … fm − 10 fc), ``mesh<m>`` (m fm ± 10 fc for
every mesh harmonic whose band starts below the top of the band), ``between`` (the rest above
the first mesh band), ``all``.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from dtwin.signal.spectrum import noise_floor

__all__ = ["ALIAS_ZONE", "ALPHA", "PASSBAND", "alias_frequencies", "GapResult", "THRESHOLD_DB", "family_threshold_db", "fold_segments", "gap", "named_bands", "levels",
           "segment_spectra", "gap_terms"]

#: Top of the band the gap is taken over, as a fraction of the sampling rate (module docs).
PASSBAND = 0.45
#: Lines above this fraction of Nyquist may be aliases of mesh lines just above Nyquist (the
#: top fifth of the band: what a DAQ filter's transition band lets through; module docs).
ALIAS_ZONE = 0.8
#: Half-width (bins) of what a line occupies in a Hann spectrum: its main lobe.
MAIN_LOBE_BINS = 2
#: Height over the measured noise floor (dB) that puts a bin into the gap's bin set.
THRESHOLD_DB = 12.0
#: Family-wise probability that noise alone puts a bin into the gap's set (:func:`gap`'s default).
ALPHA = 0.01
#: Width (bins) of the running-median noise floor.
FLOOR_BINS = 31


def fold_segments(n: int, n_folds: int = 2) -> list[slice]:
    """`n_folds` equal, contiguous segments of a record of `n` samples."""
    m = n // n_folds
    return [slice(i * m, (i + 1) * m) for i in range(n_folds)]


def segment_spectra(x: np.ndarray, sample_rate: float, n_folds: int = 2):
    """Complex Hann spectra of each segment, amplitude-scaled (``2 X / sum w``).

    `x`: (..., time). **Returns:** ``(freqs, Z)`` with Z of shape (..., n_folds, n_bins).
    """
    x = np.asarray(x)
    segs = fold_segments(x.shape[-1], n_folds)
    m = segs[0].stop - segs[0].start
    w = np.hanning(m + 1)[:-1]  # periodic Hann, as dtwin.signal.spectrum.get_window("hann")
    scale = np.full(m // 2 + 1, 2.0 / w.sum())
    scale[0] = 1.0 / w.sum()
    Z = np.stack([np.fft.rfft(x[..., s] * w, axis=-1) * scale for s in segs], axis=-2)
    return np.fft.rfftfreq(m, 1.0 / sample_rate), Z


def alias_frequencies(kin, sample_rate: float, f_max: float,
                      half_width_carrier: float = 10.0) -> np.ndarray:
    """Where mesh lines just above Nyquist show as aliases inside the scored band (Hz):
    ``fs − (m fm + n fc)`` for every line the sideband rule allows (|n| ≤
    `half_width_carrier`) whose alias lies between :data:`ALIAS_ZONE` × Nyquist and `f_max`
    (module docstring, "Aliases are not scored either")."""
    fs, fm, fc = float(sample_rate), kin.f_mesh, kin.f_carrier
    out = []
    for m in range(int(0.5 * fs // fm), int(fs // fm) + 2):
        for n in range(-int(half_width_carrier), int(half_width_carrier) + 1):
            f = m * fm + n * fc
            if not 0.5 * fs < f < fs or (kin.z_ring is not None
                                         and not kin.allowed_by_sideband_rule(m, n)):
                continue
            if ALIAS_ZONE * 0.5 * fs <= fs - f <= f_max:
                out.append(fs - f)
    return np.unique(np.asarray(out, float))


def _without(ranges: tuple, holes: np.ndarray, half_width: float) -> tuple:
    """`ranges` ((lo, hi) pairs, Hz) less ``hole ± half_width`` for every hole."""
    out = []
    for lo, hi in ranges:
        cur = lo
        for h in holes[(holes + half_width >= lo) & (holes - half_width <= hi)]:
            if h - half_width > cur:
                out.append((cur, h - half_width))
            cur = max(cur, h + half_width)
        if cur < hi:
            out.append((cur, hi))
    return tuple(out)


def named_bands(kin, f_max: float, half_width_carrier: float = 10.0,
                sample_rate: float | None = None, resolution: float = 0.0,
                f_min: float = 0.0) -> dict[str, tuple]:
    """Named frequency bands (Hz) for a gearbox's kinematics (module docstring), from `f_min`
    (Hz; ``low`` and ``all`` start there) to `f_max`. With the `sample_rate` (Hz) and the
    spectra's bin width `resolution` (Hz), the aliases of mesh lines above Nyquist
    (:func:`alias_frequencies`) are left out of every band, ± the Hann main lobe
    (:data:`MAIN_LOBE_BINS` bins)."""
    bands = _named_bands(kin, f_max, half_width_carrier, f_min)
    if sample_rate is None:
        return bands
    holes = alias_frequencies(kin, sample_rate, f_max, half_width_carrier)
    if not holes.size:
        return bands
    w = MAIN_LOBE_BINS * resolution
    return {name: _without(ranges, holes, w) for name, ranges in bands.items()}


def _named_bands(kin, f_max: float, half_width_carrier: float,
                 f_min: float = 0.0) -> dict[str, tuple]:
    """The named bands of :func:`named_bands`, aliases not yet left out."""
    hw = half_width_carrier * kin.f_carrier
    bands: dict[str, tuple] = {"all": ((f_min, f_max),)}
    mesh = []
    m = 1
    while m * kin.f_mesh - hw < f_max:
        lo, hi = m * kin.f_mesh - hw, min(m * kin.f_mesh + hw, f_max)
        bands[f"mesh{m}"] = ((lo, hi),)
        mesh.append((lo, hi))
        m += 1
    bands["low"] = ((f_min, kin.f_mesh - hw),)
    between = []
    for (_a0, a1), (b0, _) in zip(mesh[:-1], mesh[1:], strict=True):
        between.append((a1, b0))
    if mesh and mesh[-1][1] < f_max:
        between.append((mesh[-1][1], f_max))
    bands["between"] = tuple(between)
    return bands


def levels(a, floor):
    """``20 log10(A + F)`` (dB): the level of an amplitude `A` over a noise floor `F` (the
    one level formula of the gap and of discovery's fits). numpy in, numpy out; JAX arrays
    (also traced, under ``jit``) in, JAX out."""
    if isinstance(a, jax.Array) or isinstance(floor, jax.Array):
        return (20.0 / np.log(10.0)) * jnp.log(a + floor)
    return 20.0 * np.log10(np.asarray(a) + floor)


def gap_terms(a_meas: np.ndarray, a_model: np.ndarray, floor: np.ndarray,
              threshold_db: float = THRESHOLD_DB):
    """Per-bin squared level differences (dB²) and the bin mask S of the gap."""
    thr = floor * 10.0 ** (threshold_db / 20.0)
    mask = (a_meas > thr) | (a_model > thr)
    d2 = (levels(a_meas, floor) - levels(a_model, floor)) ** 2
    return d2, mask


@dataclasses.dataclass(frozen=True)
class GapResult:
    """Held-out gap (dB) overall (`total` = band ``all``) and per named band, with bin counts."""

    total: float
    bands: dict[str, float]
    counts: dict[str, int]

    def to_dict(self) -> dict:
        return dict(total=self.total, bands=self.bands, counts=self.counts)


@functools.lru_cache(maxsize=64)
def _noise_max_heights(seg_len: int, n_rows: int, lo: int, hi: int, draws: int) -> np.ndarray:
    rng = np.random.default_rng(20261124)
    out = np.empty(draws)
    for i in range(draws):
        x = rng.standard_normal(seg_len * n_rows)
        _, Z = segment_spectra(x, 1.0, n_rows)
        A = np.abs(Z)
        h = 20.0 * np.log10(A[:, lo:hi] / noise_floor(A, FLOOR_BINS)[:, lo:hi])
        out[i] = h.max()
    return np.sort(out)


def family_threshold_db(seg_len: int, n_rows: int, band: tuple[int, int],
                        alpha: float = ALPHA, draws: int = 1000) -> float:
    """Height over the running-median floor (dB) that noise alone exceeds anywhere in the bins
    ``band = (lo, hi)`` of `n_rows` Hann segments of `seg_len` samples with probability
    `alpha`: the (1 − alpha) quantile of the largest height in white-noise records sent through
    the same spectra and floor estimate (Monte Carlo, fixed seed, cached per shape). The
    estimate of the floor itself is noisy, which puts the quantile ~2 dB above the Rayleigh
    value ``10 log10(log2(n/alpha))`` (15.3 against 13.0 dB for 2 × 4500 bins); at least
    :data:`THRESHOLD_DB`."""
    heights = _noise_max_heights(int(seg_len), int(n_rows), int(band[0]), int(band[1]),
                                 int(draws))
    return max(THRESHOLD_DB, float(np.quantile(heights, 1.0 - alpha)))


#: Lowest bin of the gap: bins 0–2 hold a segment's mean (DC) and its Hann main lobe.
FIRST_BIN = 3


def gap(freqs: np.ndarray, a_meas: np.ndarray, a_model: np.ndarray,
        bands: dict[str, tuple] | None = None, floor: np.ndarray | None = None,
        threshold_db: float | None = None) -> GapResult:
    """The gap (module docstring) of amplitude spectra `a_meas`, `a_model` of shape
    (n_folds, n_bins) — each row a held-out segment — pooled over the rows.

    **Arguments:** `freqs` (Hz); spectra in the signal's unit (model scaled by its gain);
    `bands` from :func:`named_bands` (default: ``all`` only); `floor` (default: running median
    of each measured row); `threshold_db` (default: :func:`family_threshold_db` of the bins in
    the bands, per row).
    """
    a_meas = np.atleast_2d(np.asarray(a_meas))
    a_model = np.atleast_2d(np.asarray(a_model))
    if floor is None:
        floor = noise_floor(a_meas, FLOOR_BINS)
    floor = np.broadcast_to(floor, a_meas.shape)
    bands = bands or {"all": ((0.0, float(freqs[-1])),)}
    if threshold_db is None:
        in_band = np.zeros(len(freqs), bool)
        for ranges in bands.values():
            for lo, hi in ranges:
                in_band |= (freqs >= lo) & (freqs <= hi)
        idx = np.flatnonzero(in_band)
        lo = max(int(idx[0]), FIRST_BIN) if idx.size else FIRST_BIN
        hi = int(idx[-1]) + 1 if idx.size else len(freqs)
        seg_len = 2 * (len(freqs) - 1)
        threshold_db = family_threshold_db(seg_len, a_meas.shape[0], (lo, max(hi, lo + 1)))
    d2, mask = gap_terms(a_meas, a_model, floor, threshold_db)
    mask = mask & (np.arange(len(freqs)) >= FIRST_BIN)[None, :]
    out, counts = {}, {}
    for name, ranges in bands.items():
        sel = np.zeros(len(freqs), bool)
        for lo, hi in ranges:
            sel |= (freqs >= lo) & (freqs <= hi)
        mk = mask & sel[None, :]
        cnt = int(mk.sum())
        counts[name] = cnt
        out[name] = float(np.sqrt(d2[mk].mean())) if cnt else 0.0
    total = out.get("all", next(iter(out.values())))
    return GapResult(total, out, counts)
