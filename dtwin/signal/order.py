"""Shaft speed and angle, computed order tracking, order spectra, run-up waterfall and Campbell data.

Angles are in rad, speeds as shaft rotation frequencies in Hz (rev/s), orders in cycles per
revolution of the *reference shaft* (the one whose angle is used). For the planetary gearbox with
the sun as reference and the ring fixed (conventions.md), the mesh order is
``Zs Zr / (Zs + Zr)`` and the carrier order ``Zs / (Zs + Zr)``; with the carrier as reference
they are ``Zr`` and 1.

Two ways to the shaft angle ``theta(t)``:

1. **Tachometer** (:func:`tacho_angle`): rising crossings of a threshold (with hysteresis, times
   interpolated linearly between samples) mark ``theta = 2 pi k / ppr``; a monotone cubic
   (PCHIP) through them gives the angle at every sample.
2. **Mesh phase** (:func:`mesh_angle`, no tachometer): a short-time Fourier ridge of the mesh
   harmonic inside the given speed range gives a rough speed and angle; the signal is resampled
   on that rough angle, band-passed there around the mesh order (a fixed band in the order
   domain follows the run-up), and the unwrapped phase of its Hilbert transform divided by the
   mesh order is the refined angle; the resampling is repeated on the refined angle
   (`iterations`). The band must be narrower than the sideband spacing in orders (carrier order
   times N for a planetary gearbox) so that sidebands do not modulate the phase.

Angular resampling (:func:`resample_to_angle`) interpolates the signal (cubic spline) at the
times where the angle crosses a uniform grid of `samples_per_rev` points per revolution, after an
anti-aliasing low-pass at 0.4 × `samples_per_rev` × the lowest shaft speed when that lies below
the Nyquist frequency. That fixed cut-off keeps every order below 0.4 × `samples_per_rev` ×
``f_min / f_max``, so for a run-up choose ``samples_per_rev >= 2.5 × highest order × f_max / f_min``
(a tracking filter would avoid this; the fixed one is simple and zero-phase). The order spectrum of the resampled signal has resolution
``1 / revolutions`` orders; a tone locked to the shaft sits in one order bin whatever the speed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np
import scipy.interpolate
import scipy.ndimage
import scipy.signal

from ..errors import RecordError
from .spectrum import amplitude_spectrum, get_window

__all__ = [
    "CampbellData",
    "OrderMap",
    "Waterfall",
    "campbell",
    "mesh_angle",
    "order_cuts",
    "order_map",
    "order_spectrum",
    "resample_to_angle",
    "RUNUP_SPEED_CHANGE",
    "shaft_speed",
    "tacho_angle",
    "tacho_speed_range",
    "tacho_times",
    "waterfall",
]


def _signal(x, name="signal") -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1:
        raise RecordError(f"{name} must be one channel (1-D), got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise RecordError(f"{name} holds NaN or inf samples; clean or cut the record first")
    return x


def tacho_times(
    tacho: np.ndarray,
    sample_rate: float,
    *,
    threshold: float | None = None,
    hysteresis: float = 0.1,
) -> np.ndarray:
    """Times (s) of the rising threshold crossings of a tachometer signal.

    **Arguments:**

    - `tacho`: the tachometer samples (any unit: volts, a pulse train).
    - `sample_rate`: sampling rate (Hz).
    - `threshold`: crossing level (unit of `tacho`); default midway between min and max.
    - `hysteresis`: fraction of the signal's range it must fall below the threshold before the
      next rising crossing counts (a Schmitt trigger against noise on the edges).

    **Returns:** crossing times, linearly interpolated between the samples around each crossing.
    """
    x = _signal(tacho, "tacho")
    lo, hi = float(x.min()), float(x.max())
    if hi - lo <= 0:
        raise RecordError("the tachometer channel is constant: no pulses to count")
    thr = 0.5 * (lo + hi) if threshold is None else float(threshold)
    rising = np.flatnonzero((x[:-1] < thr) & (x[1:] >= thr))
    low = np.flatnonzero(x < thr - hysteresis * (hi - lo))
    keep = []
    last = -1
    for i in rising:  # accept a crossing only if the signal went low since the last one
        j = np.searchsorted(low, last + 1)
        if last < 0 or (j < low.size and low[j] <= i):
            keep.append(i)
            last = i
    idx = np.asarray(keep, dtype=np.int64)
    frac = (thr - x[idx]) / (x[idx + 1] - x[idx])
    return (idx + frac) / float(sample_rate)


def tacho_angle(
    tacho: np.ndarray,
    sample_rate: float,
    ppr: int,
    *,
    threshold: float | None = None,
    hysteresis: float = 0.1,
) -> np.ndarray:
    """Shaft angle (rad) at every sample from a tachometer with `ppr` pulses per revolution.

    Pulse k (0, 1, …) is at ``theta = 2 pi k / ppr``, so the angle is 0 at the first pulse. A
    PCHIP through the pulses gives the angle in between and is extended linearly before the first
    and after the last pulse with the speed of the neighbouring interval. See
    :func:`tacho_times` for `threshold` and `hysteresis`.
    """
    if int(ppr) < 1:
        raise RecordError(f"pulses per revolution must be a positive integer, got {ppr}")
    x = _signal(tacho, "tacho")
    times = tacho_times(x, sample_rate, threshold=threshold, hysteresis=hysteresis)
    if times.size < 3:
        raise RecordError(
            f"the tachometer gave {times.size} pulses; at least 3 are needed (check ppr, the "
            "threshold or the record length)"
        )
    ang = 2 * np.pi * np.arange(times.size) / int(ppr)
    t = np.arange(x.size) / float(sample_rate)
    out = scipy.interpolate.PchipInterpolator(times, ang, extrapolate=False)(t)
    first, last = t < times[0], t > times[-1]
    out[first] = ang[0] + (t[first] - times[0]) * (ang[1] - ang[0]) / (times[1] - times[0])
    out[last] = ang[-1] + (t[last] - times[-1]) * (ang[-1] - ang[-2]) / (times[-1] - times[-2])
    return out


def shaft_speed(angle: np.ndarray, sample_rate: float) -> np.ndarray:
    """Shaft rotation frequency (Hz) at every sample: ``dtheta/dt / 2 pi`` (central differences)."""
    return np.gradient(np.asarray(angle, dtype=np.float64)) * float(sample_rate) / (2 * np.pi)


#: Relative change of the speed within a record (2nd to 98th percentile over the median) above
#: which the record is a run-up or coast-down, not a steady run.
RUNUP_SPEED_CHANGE = 0.03


def tacho_speed_range(tacho: np.ndarray, sample_rate: float, ppr: int) -> tuple[float, float, float]:
    """The 2nd percentile, 98th percentile and median (Hz) of the speed of the shaft a
    tachometer (`ppr` pulses per revolution) is on, over the record."""
    fs = float(sample_rate)
    sp = np.asarray(shaft_speed(tacho_angle(np.asarray(tacho, dtype=np.float64), fs, int(ppr)),
                                fs), dtype=float)
    return float(np.percentile(sp, 2)), float(np.percentile(sp, 98)), float(np.median(sp))


def _check_angle(angle: np.ndarray, n: int) -> np.ndarray:
    angle = np.asarray(angle, dtype=np.float64)
    if angle.shape != (n,):
        raise RecordError(f"angle must have one value per sample ({n}), got shape {angle.shape}")
    if not np.all(np.diff(angle) > 0):
        raise RecordError(
            "the shaft angle must increase strictly (the shaft stands still or turns backwards "
            "somewhere); cut the record to the part where it turns"
        )
    return angle


def resample_to_angle(
    x: np.ndarray,
    sample_rate: float,
    angle: np.ndarray,
    samples_per_rev: int,
    *,
    anti_alias: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Resample `x` on a uniform grid of the shaft angle (computed order tracking).

    **Arguments:**

    - `x`: the signal (one channel), sampled at `sample_rate` (Hz).
    - `angle`: the shaft angle (rad) at every sample, strictly increasing.
    - `samples_per_rev`: points per revolution of the grid (orders up to half of it are kept).
    - `anti_alias`: low-pass (8th-order Butterworth, zero phase) at 0.4 × `samples_per_rev` ×
      the lowest shaft speed before resampling when that cut-off is below 0.45 × `sample_rate`.

    **Returns:** ``(angle_grid, x_angle)``: grid angles (rad, multiples of
    ``2 pi / samples_per_rev`` inside the record) and the resampled signal.
    """
    x = _signal(x)
    fs = float(sample_rate)
    angle = _check_angle(angle, x.size)
    spr = int(samples_per_rev)
    if spr < 4:
        raise RecordError(f"samples_per_rev must be at least 4, got {samples_per_rev}")
    if anti_alias:
        f_min = float(np.min(shaft_speed(angle, fs)))
        cutoff = 0.4 * spr * f_min
        if 0 < cutoff < 0.45 * fs:
            sos = scipy.signal.butter(8, cutoff, fs=fs, output="sos")
            x = scipy.signal.sosfiltfilt(sos, x)
    step = 2 * np.pi / spr
    k0, k1 = int(np.ceil(angle[0] / step)), int(np.floor(angle[-1] / step))
    grid = np.arange(k0, k1 + 1) * step
    t = np.arange(x.size) / fs
    t_grid = np.interp(grid, angle, t)
    return grid, scipy.interpolate.make_interp_spline(t, x, k=3)(t_grid)


def order_spectrum(
    x_angle: np.ndarray, samples_per_rev: int, window: str = "hann", *, whole_revs: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude spectrum over shaft orders of an angle-resampled signal.

    With `whole_revs` the signal is cut to a whole number of revolutions, so integer orders fall
    on bins. **Returns:** ``(orders, amplitude)``: orders (cycles/rev, resolution
    ``1 / revolutions``) and amplitudes (unit of the signal, a locked tone of amplitude A reads A
    on a bin, see :func:`dtwin.signal.spectrum.amplitude_spectrum`).
    """
    x = _signal(x_angle)
    spr = int(samples_per_rev)
    if whole_revs:
        x = x[: (x.size // spr) * spr]
    if x.size < 2 * spr:
        raise RecordError("an order spectrum needs at least two revolutions of the shaft")
    return amplitude_spectrum(x, float(spr), window)


def _ridge(x, fs, f_lo, f_hi, seg_duration):
    nper = int(min(x.size, max(64, round(seg_duration * fs))))
    f, t, z = scipy.signal.stft(x, fs=fs, window="hann", nperseg=nper, noverlap=nper * 3 // 4,
                                boundary=None, padded=False)
    band = np.flatnonzero((f >= f_lo) & (f <= f_hi))
    if band.size < 3:
        raise RecordError(
            f"the mesh band {f_lo:.1f}–{f_hi:.1f} Hz holds fewer than 3 STFT bins; widen "
            "speed_range or lengthen the record"
        )
    mag = np.log(np.abs(z[band]) + 1e-300)
    k = np.clip(np.argmax(mag, axis=0), 1, band.size - 2)
    cols = np.arange(mag.shape[1])
    a, b, c = mag[k - 1, cols], mag[k, cols], mag[k + 1, cols]
    denom = a - 2 * b + c
    delta = np.where(np.abs(denom) > 0, 0.5 * (a - c) / np.where(denom == 0, 1, denom), 0.0)
    ridge = f[band][k] + np.clip(delta, -0.5, 0.5) * (f[1] - f[0])
    return t, scipy.ndimage.median_filter(ridge, size=min(5, ridge.size), mode="nearest")


def mesh_angle(
    x: np.ndarray,
    sample_rate: float,
    mesh_order: float,
    speed_range: tuple[float, float],
    *,
    bandwidth: float = 0.1,
    iterations: int = 2,
    segment_duration: float = 0.1,
) -> np.ndarray:
    """Reference-shaft angle (rad) at every sample from the phase of a mesh harmonic.

    **Arguments:**

    - `x`: the vibration signal (one channel) at `sample_rate` (Hz).
    - `mesh_order`: the harmonic tracked, in orders of the reference shaft (e.g. the mesh order
      ``Zs Zr / (Zs + Zr)`` of the sun for a planetary gearbox).
    - `speed_range`: (lowest, highest) reference-shaft speed in the record (Hz): the STFT ridge
      of the harmonic is searched in ``mesh_order * speed_range``.
    - `bandwidth`: half-width of the band-pass around `mesh_order` in orders; keep it below the
      spacing of the nearest sidebands (module docstring).
    - `iterations`: passes of resampling + phase demodulation.
    - `segment_duration`: STFT segment (s) for the rough ridge.

    **Returns:** the angle (rad), 0 at the first sample, defined up to a multiple of
    ``2 pi / mesh_order`` (the mesh phase cannot tell teeth apart). Within ``1 / (2 bandwidth)``
    revolutions of either end (the band-pass's edge transients) the angle follows the shape of
    the previous pass (the STFT ridge on the first), joined continuously.
    """
    x = _signal(x)
    fs = float(sample_rate)
    lo, hi = float(speed_range[0]), float(speed_range[1])
    if not 0 < lo < hi:
        raise RecordError(f"speed_range must be (low, high) in Hz with 0 < low < high, got {speed_range}")
    mo = float(mesh_order)
    if not 0 < bandwidth < mo:
        raise RecordError(f"bandwidth must lie between 0 and the mesh order {mo}, got {bandwidth}")
    if mo * hi >= 0.5 * fs:
        raise RecordError(
            f"the mesh harmonic reaches {mo * hi:.0f} Hz, above the Nyquist frequency {fs / 2:.0f} "
            "Hz; track a lower harmonic or give a lower speed_range"
        )
    t = np.arange(x.size) / fs
    tr, ridge = _ridge(x, fs, mo * lo, mo * hi, segment_duration)
    speed = np.interp(t, tr, ridge / mo)
    angle = 2 * np.pi * np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) / fs)))
    # the anti-alias low-pass at 0.4 spr * lowest speed must pass the harmonic at the highest
    spr = int(2 ** np.ceil(np.log2(max(6 * (mo + bandwidth), 2.5 * (mo + bandwidth) * hi / lo))))
    for _ in range(max(1, int(iterations))):
        grid, xa = resample_to_angle(x, fs, angle, spr, anti_alias=True)
        sos = scipy.signal.butter(4, [mo - bandwidth, mo + bandwidth], btype="band", fs=spr,
                                  output="sos")
        phase = np.unwrap(np.angle(scipy.signal.hilbert(scipy.signal.sosfiltfilt(sos, xa))))
        # the band-pass's edge transients: keep the phase only 1/(2 bandwidth) revolutions
        # inside the grid, and continue it outside with the previous angle's shape
        edge = int(np.ceil(spr / (2 * bandwidth)))
        if grid.size <= 2 * edge + 2:
            raise RecordError(
                f"the record covers {grid.size / spr:.1f} revolutions, too few for a band of "
                f"±{bandwidth} orders (edge transients of {edge / spr:.1f} revolutions each side); "
                "lengthen the record or widen `bandwidth`"
            )
        g, ph = grid[edge:-edge], phase[edge:-edge]
        new = np.interp(angle, g, ph, left=np.nan, right=np.nan) / mo
        ok = np.flatnonzero(np.isfinite(new))
        i0, i1 = ok[0], ok[-1]
        new[:i0] = new[i0] + angle[:i0] - angle[i0]
        new[i1 + 1 :] = new[i1] + angle[i1 + 1 :] - angle[i1]
        angle = new - new[0]
        if not np.all(np.diff(angle) > 0):
            raise RecordError(
                "the mesh-phase angle does not increase everywhere: the harmonic is too weak or "
                "the band holds other lines; narrow `bandwidth`, check `mesh_order` and "
                "`speed_range`, or use a tachometer"
            )
    return angle


@dataclasses.dataclass(frozen=True)
class Waterfall:
    """Short-time amplitude spectra of a record.

    - `times`: segment centres (s).
    - `freqs`: bin frequencies (Hz).
    - `amplitude`: shape ``(freq, time)``, amplitude-corrected (a tone of amplitude A reads A on a
      bin), unit of the signal.
    - `speed`: reference-shaft speed (Hz) averaged over each segment, or None without an angle.
    """

    times: np.ndarray
    freqs: np.ndarray
    amplitude: np.ndarray
    speed: np.ndarray | None


def waterfall(
    x: np.ndarray,
    sample_rate: float,
    *,
    segment_length: int = 1024,
    overlap: float = 0.75,
    window: str = "hann",
    angle: np.ndarray | None = None,
) -> Waterfall:
    """Run-up waterfall: amplitude spectra of overlapping segments (STFT, scipy.signal.stft).

    **Arguments:** `x` (one channel) at `sample_rate` (Hz); `segment_length` (samples, resolution
    ``sample_rate / segment_length``); `overlap` (fraction); `window` (:data:`WINDOWS`); `angle`:
    the reference-shaft angle (rad) at every sample, to attach the speed of each segment.
    """
    x = _signal(x)
    fs = float(sample_rate)
    nper = int(segment_length)
    if not 4 <= nper <= x.size:
        raise RecordError(f"segment_length must lie between 4 and {x.size} samples, got {nper}")
    nover = int(round(overlap * nper))
    w = get_window(window, nper)
    f, t, z = scipy.signal.stft(x, fs=fs, window=w, nperseg=nper, noverlap=nover,
                                boundary=None, padded=False, detrend=False, scaling="spectrum")
    amp = np.abs(z)  # scaling="spectrum" divides by sum(w)
    amp[1:] *= 2.0
    if nper % 2 == 0:
        amp[-1] /= 2.0
    speed = None
    if angle is not None:
        angle = _check_angle(angle, x.size)
        start = np.round(t * fs).astype(int) - nper // 2
        stop = np.minimum(start + nper - 1, x.size - 1)
        speed = (angle[stop] - angle[start]) / ((stop - start) / fs) / (2 * np.pi)
    return Waterfall(t, f, amp, speed)


@dataclasses.dataclass(frozen=True)
class CampbellData:
    """Campbell diagram data: waterfall amplitudes against shaft speed with overlays.

    - `speed`: reference-shaft speed of each segment (Hz), ascending.
    - `freqs`: frequencies (Hz); `amplitude`: ``(freq, speed)`` (signal unit).
    - `order_lines`: name → frequencies (Hz) ``order * speed`` of each order.
    - `natural_frequencies`: name → natural frequency (Hz), horizontal lines.
    """

    speed: np.ndarray
    freqs: np.ndarray
    amplitude: np.ndarray
    order_lines: dict[str, np.ndarray]
    natural_frequencies: dict[str, float]


def campbell(
    wf: Waterfall,
    orders: Mapping[str, float],
    natural_frequencies: Mapping[str, float] | Sequence[float] = (),
) -> CampbellData:
    """Campbell data from a waterfall with speeds (:func:`waterfall` with `angle`).

    **Arguments:** `orders`: name → order (e.g. ``{"fm": 16.68, "2fm": 33.35}``) of the
    reference shaft; `natural_frequencies`: the twin's natural frequencies (Hz), as a mapping
    name → value or a sequence (named ``f1, f2, …``). Crossings of an order line and a natural
    frequency are the speeds at which that order excites the mode.
    """
    if wf.speed is None:
        raise RecordError("a Campbell diagram needs the shaft speed: build the waterfall with angle=")
    idx = np.argsort(wf.speed)
    speed = wf.speed[idx]
    lines = {str(k): float(v) * speed for k, v in orders.items()}
    if isinstance(natural_frequencies, Mapping):
        nat = {str(k): float(v) for k, v in natural_frequencies.items()}
    else:
        nat = {f"f{i + 1}": float(v) for i, v in enumerate(natural_frequencies)}
    return CampbellData(speed, wf.freqs, wf.amplitude[:, idx], lines, nat)


@dataclasses.dataclass(frozen=True)
class OrderMap:
    """Order spectra of successive stretches of a run-up (order vs speed colour map).

    - `speed`: mean reference-shaft speed of each stretch (Hz), ascending; ``60 × speed`` is rpm.
    - `orders`: order bins (cycles per revolution, resolution ``1 / revs_per_segment``).
    - `amplitude`: shape ``(order, speed)``, amplitude-corrected (a locked tone of amplitude A on a
      bin reads A), unit of the signal.
    - `times`: centre time (s) of each stretch, in the order of `speed`.
    - `revs_per_segment`, `window`: the stretch length (revolutions) and its window;
      `enbw_bins`: the window's equivalent noise bandwidth (bins), for :func:`order_cuts`.
    """

    speed: np.ndarray
    orders: np.ndarray
    amplitude: np.ndarray
    times: np.ndarray
    revs_per_segment: int
    window: str
    enbw_bins: float = 1.5

    @property
    def rpm(self) -> np.ndarray:
        """Reference-shaft speed of each stretch (rev/min)."""
        return 60.0 * self.speed


def order_map(
    x: np.ndarray,
    sample_rate: float,
    angle: np.ndarray,
    *,
    max_order: float,
    revs_per_segment: int = 4,
    overlap: float = 0.5,
    window: str = "hann",
    samples_per_rev: int | None = None,
) -> OrderMap:
    """Order map of a run-up or coast-down: the signal is resampled on the shaft angle
    (:func:`resample_to_angle`), cut into stretches of `revs_per_segment` revolutions overlapping
    by `overlap`, and each stretch's order spectrum is taken (:func:`order_spectrum` scaling),
    tagged with the stretch's mean speed.

    **Arguments:**

    - `x`: one channel at `sample_rate` (Hz); `angle`: the reference-shaft angle (rad) at every
      sample, from :func:`tacho_angle` or :func:`mesh_angle`.
    - `max_order`: highest order kept (cycles/rev).
    - `revs_per_segment`: revolutions per stretch (order resolution ``1 / revs_per_segment``,
      speed resolution: the speed change over a stretch).
    - `overlap`: fraction of a stretch shared with the next.
    - `samples_per_rev`: angular sampling; default a power of two at least
      ``2.5 × max_order × f_max / f_min`` (the anti-alias rule of :func:`resample_to_angle`).

    **Returns:** an :class:`OrderMap`.
    """
    x = _signal(x)
    fs = float(sample_rate)
    angle = _check_angle(angle, x.size)
    if not max_order > 0:
        raise RecordError(f"max_order must be positive, got {max_order}")
    speed = shaft_speed(angle, fs)
    f_lo, f_hi = float(np.min(speed)), float(np.max(speed))
    if f_lo <= 0:
        raise RecordError("the shaft stands still in part of the record; cut it to where it turns")
    if samples_per_rev is None:
        need = max(2.5 * max_order * f_hi / f_lo, 4.0 * max_order, 8.0)
        samples_per_rev = int(2 ** np.ceil(np.log2(need)))
    spr = int(samples_per_rev)
    grid, xa = resample_to_angle(x, fs, angle, spr)
    t_grid = np.interp(grid, angle, np.arange(x.size) / fs)
    nper = int(revs_per_segment) * spr
    if int(revs_per_segment) < 1 or nper > xa.size:
        raise RecordError(f"revs_per_segment must lie between 1 and the record's "
                          f"{xa.size // spr} revolutions, got {revs_per_segment}")
    if not 0 <= overlap < 1:
        raise RecordError(f"overlap must be a fraction in [0, 1), got {overlap}")
    hop = max(1, int(round((1 - overlap) * nper)))
    starts = np.arange(0, xa.size - nper + 1, hop)
    w = get_window(window, nper)
    segs = np.stack([xa[s : s + nper] for s in starts])
    segs = segs - segs.mean(axis=1, keepdims=True)
    amp = np.abs(np.fft.rfft(segs * w, axis=1)) / w.sum()
    amp[:, 1:] *= 2.0
    if nper % 2 == 0:
        amp[:, -1] /= 2.0
    orders = np.fft.rfftfreq(nper, 1.0 / spr)
    keep = orders <= max_order
    dt = t_grid[starts + nper - 1] - t_grid[starts]
    seg_speed = (nper - 1) / spr / dt
    centre = 0.5 * (t_grid[starts + nper - 1] + t_grid[starts])
    idx = np.argsort(seg_speed, kind="stable")
    enbw = float(nper * np.sum(w * w) / w.sum() ** 2)
    return OrderMap(seg_speed[idx], orders[keep], amp[idx][:, keep].T, centre[idx],
                    int(revs_per_segment), window, enbw)


def order_cuts(om: OrderMap, orders: Mapping[str, float], *, half_width_bins: int = 2) -> dict[str, np.ndarray]:
    """Amplitude of each order against speed (order cuts / order tracks) from an
    :class:`OrderMap`.

    The amplitude of order ``o`` in a stretch is the root of the power summed over the bins
    within `half_width_bins` of ``o``, divided by the window's equivalent noise bandwidth in bins
    (Parseval): a locked tone of amplitude A reads A wherever it falls between bins (the Hann
    main lobe spans ±2 bins). **Returns:** name → amplitude (unit of the signal), one value per
    ``om.speed``; orders beyond the map's range give NaN.
    """
    d_o = float(om.orders[1] - om.orders[0])
    out = {}
    for name, o in orders.items():
        k = int(round(float(o) / d_o))
        lo, hi = k - half_width_bins, k + half_width_bins
        if lo < 1 or hi >= om.orders.size:
            out[str(name)] = np.full(om.speed.shape, np.nan)
            continue
        out[str(name)] = np.sqrt(np.sum(om.amplitude[lo : hi + 1] ** 2, axis=0) / om.enbw_bins)
    return out
