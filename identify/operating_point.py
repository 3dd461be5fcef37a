"""The operating point from the data, before any fit: input speed, or its profile in a run-up.

A twin simulated at the nominal 1800 rpm cannot match a bench that turned at 1782 rpm: every
mesh harmonic and sideband would sit in the wrong bins. So the speed is measured first:

**Steady record** (:func:`estimate_speed`):

1. with a tachometer channel: the mean speed from its pulses (:func:`dtwin.order.tacho_angle`);
2. otherwise from the spectrum (Hann window, zero padding ×4): a harmonic-sum search within
   ±`search` (default 5 %) of the nominal speed, then each mesh harmonic ``h`` below 0.45 × the
   rate standing 10 dB above the floor (running median over 101 bins) is interpolated (parabola on the log amplitude); each
   gives ``f_mesh = f_h / h`` with a precision ~ ``1/(h T SNR)``, so they are averaged with
   weights ``h²`` (a higher harmonic pins the speed more precisely). The carrier sidebands ``f_mesh ± k N f_carrier`` confirm the line: a line
   whose ``± N f_carrier`` neighbours are not above the floor is reported as ``weak``.

**Run-up / coast-down** (:func:`estimate_speed_profile`): the shaft angle from the tachometer, or
a per-frame harmonic-sum speed and a de-chirp refinement, giving the straight line
``f_sun(t) = f0 + (f1 - f0) t / T`` (the twin's ramp set point).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from dtwin.errors import RecordError
from dtwin.kinematics import Kinematics
from dtwin.order import shaft_speed, tacho_angle
from dtwin.spectrum import noise_floor

__all__ = ["OperatingPoint", "SpeedProfileEstimate", "estimate_speed", "estimate_speed_profile",
           "gear_orders"]


def gear_orders(twin) -> dict[str, float]:
    """Orders of the input (sun) speed: ``mesh``, ``carrier``, ``sun_fault`` (f / f_sun)."""
    return Kinematics.from_gear_set(twin.lp, 1.0).orders()


@dataclasses.dataclass(frozen=True)
class OperatingPoint:
    """Input speed of a steady record.

    - `f_sun` (Hz), `f_mesh` (Hz); `std_f_sun` (Hz): spread of the harmonics' estimates divided
      by the square root of their number (0 from a tachometer);
    - `method`: ``tacho`` or ``spectrum``; `harmonics`: per harmonic ``(h, f_h Hz, level dB
      above floor)``; `weak`: the fundamental's carrier sidebands were not found.
    """

    f_sun: float
    f_mesh: float
    std_f_sun: float
    method: str
    harmonics: tuple[tuple[int, float, float], ...] = ()
    weak: bool = False


def _peak(freqs, amp, lo, hi):
    sel = np.flatnonzero((freqs >= lo) & (freqs <= hi))
    if sel.size < 3:
        return None
    k = sel[np.argmax(amp[sel])]
    if k <= 0 or k >= amp.size - 1:
        return float(freqs[k]), float(amp[k])
    a, b, c = np.log(amp[k - 1 : k + 2] + 1e-300)
    den = a - 2 * b + c
    d = 0.0 if den == 0 else float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))
    return float(freqs[k] + d * (freqs[1] - freqs[0])), float(np.exp(b - 0.25 * (a - c) * d))


def _harmonic_sum(freqs, amp, floor, cands, mesh_order, fs, harmonics):
    """Score of each candidate speed: sum over mesh harmonics of log(level / floor)."""
    score = np.zeros(cands.shape)
    la = np.log(amp + 1e-300) - np.log(floor)
    for h in range(1, harmonics + 1):
        fh = h * mesh_order * cands
        ok = fh < 0.45 * fs
        if not ok.any():
            break
        score[..., :] += np.where(ok, np.interp(np.where(ok, fh, 0.0), freqs, la), 0.0)
    return score


def estimate_speed(
    record, twin, f_sun_nominal: float, *, channel: int | str = 0, search: float = 0.05,
    max_harmonics: int = 8, min_level_db: float = 10.0,
) -> OperatingPoint:
    """Input speed of a steady record (module docstring).

    **Arguments:** `record` (`dtwin.io.Record`); `twin` (tooth numbers); `f_sun_nominal` (Hz);
    `channel`; `search`: relative half-width of the search window; `max_harmonics`;
    `min_level_db`: a harmonic counts when it stands this far above the noise floor.

    A coarse speed maximises the sum over the harmonics of the log level above the floor (a
    harmonic-sum estimator: a noise peak near one harmonic cannot win against all of them);
    each harmonic's peak within ±1.5 bins of that comb is then interpolated (parabola on the
    log amplitude) and the speeds are averaged with weights ``h²``.

    **Returns:** :class:`OperatingPoint`.
    """
    fs = float(record.sample_rate)
    orders = gear_orders(twin)
    if record.tacho is not None and record.tacho_ppr:
        ang = tacho_angle(np.asarray(record.tacho), fs, int(record.tacho_ppr))
        f = float(np.mean(shaft_speed(ang, fs)))
        if record.tacho_shaft == "carrier":
            f = f / orders["carrier"]
        return OperatingPoint(f, f * orders["mesh"], 0.0, "tacho")
    x = np.asarray(record.channel(channel), dtype=np.float64)
    if not np.all(np.isfinite(x)):
        raise RecordError("the record holds NaN or inf samples; clean or cut it first")
    n = x.size
    pad = 4
    xp = np.concatenate([(x - x.mean()) * np.hanning(n), np.zeros((pad - 1) * n)])
    amp = np.abs(np.fft.rfft(xp))
    freqs = np.fft.rfftfreq(pad * n, 1.0 / fs)
    floor = noise_floor(amp, pad * 101 + 1)
    mo = orders["mesh"]
    df = fs / n  # one bin of the unpadded record
    cands = f_sun_nominal * (1 + np.linspace(-search, search, int(8 * search * f_sun_nominal
                                                                  * mo * max_harmonics / df) + 3))
    coarse = float(cands[np.argmax(_harmonic_sum(freqs, amp, floor, cands, mo, fs, max_harmonics))])
    found = []
    for h in range(1, max_harmonics + 1):
        c = h * mo * coarse
        if c + 2 * df > 0.45 * fs:
            break
        p = _peak(freqs, amp, c - 1.5 * df, c + 1.5 * df)
        if p is None:
            continue
        level = 20 * np.log10(p[1] / float(np.interp(p[0], freqs, floor)))
        if level >= min_level_db:
            found.append((h, p[0], float(level)))
    if not found:
        best = float(np.max(_harmonic_sum(freqs, amp, floor, np.array([coarse]), mo, fs,
                                          max_harmonics)))
        if best <= 0:
            raise RecordError(
                f"no mesh harmonic stands above the noise near {f_sun_nominal * mo:.1f} Hz "
                f"(±{100 * search:.0f} %): check the spec's speed (operating.f_sun), the "
                "channel, or pass the speed explicitly"
            )
        # no single harmonic is clear, but the comb is: keep the harmonic-sum speed
        return OperatingPoint(coarse, coarse * mo, 0.5 * df / mo, "spectrum", (), True)
    h = np.array([f[0] for f in found], dtype=float)
    fm = np.array([f[1] / f[0] for f in found])
    w = h**2
    f_mesh = float(np.sum(w * fm) / np.sum(w))
    std = float(np.std(fm) / np.sqrt(len(fm))) / mo if len(fm) > 1 else 0.0
    spacing = twin.lp.n_planets * orders["carrier"] * f_mesh / mo
    weak = True
    for s_ in (-spacing, spacing):
        p = _peak(freqs, amp, f_mesh + s_ - 0.2 * spacing, f_mesh + s_ + 0.2 * spacing)
        if p is not None and p[1] > 2.0 * np.interp(p[0], freqs, floor):
            weak = False
    return OperatingPoint(f_mesh / mo, f_mesh, std, "spectrum", tuple(found), weak)


@dataclasses.dataclass(frozen=True)
class SpeedProfileEstimate:
    """Input-speed profile of a run-up/coast-down: per-sample `speed` (Hz) and the fitted
    straight line `f_start` → `f_end` (Hz) over the record (`duration` s); `rms_error` (Hz) of
    the line; `method` (``tacho``/``mesh_phase``)."""

    speed: np.ndarray
    f_start: float
    f_end: float
    duration: float
    rms_error: float
    method: str


def _dechirp_energy(x, t, mo, harmonics, fs, f0, f1, T):
    ang = 2 * np.pi * (f0 * t + 0.5 * (f1 - f0) / T * t * t)
    w = np.hanning(x.size)
    e = 0.0
    for h in range(1, harmonics + 1):
        if h * mo * max(f0, f1) > 0.45 * fs:
            break
        e += np.abs(np.sum(w * x * np.exp(-1j * h * mo * ang))) ** 2
    return e


def estimate_speed_profile(
    record, twin, speed_range: tuple[float, float], *, channel: int | str = 0,
    harmonics: int = 6, segment: float = 0.04,
) -> SpeedProfileEstimate:
    """Input-speed profile of a run-up or coast-down, taken as a linear ramp.

    With a tachometer: the angle from its pulses. Otherwise: per short-time frame (`segment`
    s, half overlap) the speed that maximises the harmonic sum of the mesh harmonics (module
    :func:`estimate_speed`'s comb) inside `speed_range` (Hz); a straight line through those
    speeds (least squares) gives the start and end; then the line is refined by maximising the
    energy of the record demodulated ("de-chirped") at the first `harmonics` mesh orders along
    the ramp's angle ``2 pi (f0 t + (f1 - f0) t² / 2T)`` (Nelder–Mead): a maximum-likelihood
    estimate of a linear chirp, precise to a small fraction of ``1 / (T × mesh order)`` Hz.

    **Returns:** :class:`SpeedProfileEstimate`.
    """
    import scipy.optimize
    import scipy.signal

    fs = float(record.sample_rate)
    orders = gear_orders(twin)
    mo = orders["mesh"]
    T = record.duration
    x = np.asarray(record.channel(channel), dtype=np.float64)
    if not np.all(np.isfinite(x)):
        raise RecordError("the record holds NaN or inf samples; clean or cut it first")
    t = np.arange(x.size) / fs
    if record.tacho is not None and record.tacho_ppr:
        ang = tacho_angle(np.asarray(record.tacho), fs, int(record.tacho_ppr))
        if record.tacho_shaft == "carrier":
            ang = ang / orders["carrier"]
        speed = shaft_speed(ang, fs)
        a = np.vstack([t, 0.5 * t**2, np.ones_like(t)]).T
        coef, *_ = np.linalg.lstsq(a, ang / (2 * np.pi), rcond=None)
        f0, f1 = float(coef[0]), float(coef[0] + coef[1] * T)
        line = f0 + (f1 - f0) * t / T
        return SpeedProfileEstimate(speed, f0, f1, T, float(np.sqrt(np.mean((speed - line) ** 2))),
                                    "tacho")
    lo, hi = float(speed_range[0]), float(speed_range[1])
    if not 0 < lo < hi:
        raise RecordError(f"speed_range must be (low, high) in Hz, got {speed_range}")
    seg = int(round(segment * fs))
    f, tt, Z = scipy.signal.stft(x - x.mean(), fs=fs, window="hann", nperseg=seg,
                                 noverlap=seg // 2, boundary=None, padded=False)
    A = np.abs(Z)
    cands = np.linspace(lo, hi, 2001)
    best = []
    for j in range(A.shape[1]):
        fl = noise_floor(A[:, j], 31)
        best.append(cands[np.argmax(_harmonic_sum(f, A[:, j], fl, cands, mo, fs, harmonics))])
    best = np.asarray(best)
    coef = np.polyfit(tt, best, 1)
    resid = best - np.polyval(coef, tt)
    keep = np.abs(resid) <= 3 * np.median(np.abs(resid)) + 1e-9
    coef = np.polyfit(tt[keep], best[keep], 1)
    f0, f1 = float(np.polyval(coef, 0.0)), float(np.polyval(coef, T))
    res = scipy.optimize.minimize(
        lambda v: -_dechirp_energy(x - x.mean(), t, mo, harmonics, fs, v[0], v[1], T),
        np.array([f0, f1]), method="Nelder-Mead",
        options=dict(xatol=1e-5, fatol=1e-10, initial_simplex=np.array(
            [[f0, f1], [f0 + 0.05, f1], [f0, f1 + 0.05]])))
    f0, f1 = float(res.x[0]), float(res.x[1])
    speed = np.interp(t, tt, best)
    line = f0 + (f1 - f0) * t / T
    return SpeedProfileEstimate(speed, f0, f1, T, float(np.sqrt(np.mean((speed - line) ** 2))),
                                "harmonic_sum+dechirp")
