"""The operating point from the data, before any fit: input speed, or its profile in a run-up.

A twin simulated at the nominal 1800 rpm cannot match a bench that turned at 1782 rpm: every
mesh harmonic and sideband would sit in the wrong bins. So the speed is measured first:

**Steady record** (:func:`estimate_speed`):

1. with a tachometer channel: the mean speed from its pulses (:func:`dtwin.order.tacho_angle`);
2. otherwise from the spectrum: the largest line within ±`search` (default 5 %) of the nominal
   mesh frequency of each harmonic ``h = 1 … H`` below 0.45 × the rate is located (Hann window,
   zero padding ×4, parabolic interpolation of the log amplitude around the maximum bin); each
   harmonic gives ``f_mesh = f_h / h``, with a precision ~ ``1/(h T SNR)``: the estimates are
   averaged with weights ``h² × level above the noise floor`` (a higher harmonic pins the speed
   more precisely). The carrier sidebands ``f_mesh ± k N f_carrier`` confirm the line: a line
   whose ``± N f_carrier`` neighbours are not above the floor is reported as ``weak``.

**Run-up / coast-down** (:func:`estimate_speed_profile`): the shaft angle from the tachometer or
from the phase of the mesh harmonic (:func:`dtwin.order.mesh_angle`), its speed, and the least-
squares straight line ``f_sun(t) = f0 + (f1 - f0) t / T`` (the twin's ramp set point).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from dtwin.errors import RecordError

__all__ = ["OperatingPoint", "SpeedProfileEstimate", "estimate_speed", "estimate_speed_profile",
           "gear_orders"]


def gear_orders(twin) -> dict[str, float]:
    """Orders of the input (sun) speed: ``mesh``, ``carrier``, ``sun_fault`` (f / f_sun)."""
    lp = twin.lp
    zs, zr, n = lp.z_sun, lp.z_ring, lp.n_planets
    carrier = zs / (zs + zr)
    mesh = carrier * zr
    return {"mesh": mesh, "carrier": carrier, "sun_fault": mesh * n / zs,
            "planet_fault": mesh / lp.z_planet}


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


def estimate_speed(
    record, twin, f_sun_nominal: float, *, channel: int | str = 0, search: float = 0.05,
    max_harmonics: int = 8,
) -> OperatingPoint:
    """Input speed of a steady record (module docstring).

    **Arguments:** `record` (`dtwin.io.Record`); `twin` (tooth numbers); `f_sun_nominal` (Hz);
    `channel`; `search`: relative half-width of the search window; `max_harmonics`.

    **Returns:** :class:`OperatingPoint`.
    """
    from dtwin.spectrum import noise_floor

    fs = float(record.sample_rate)
    orders = gear_orders(twin)
    if record.tacho is not None and record.tacho_ppr:
        from dtwin.order import shaft_speed, tacho_angle

        ang = tacho_angle(np.asarray(record.tacho), fs, int(record.tacho_ppr))
        f = float(np.mean(shaft_speed(ang, fs)))
        if record.tacho_shaft == "carrier":
            f = f / orders["carrier"]
        return OperatingPoint(f, f * orders["mesh"], 0.0, "tacho")
    x = np.asarray(record.channel(channel), dtype=np.float64)
    if not np.all(np.isfinite(x)):
        raise RecordError("the record holds NaN or inf samples; clean or cut it first")
    n = x.size
    xp = np.concatenate([(x - x.mean()) * np.hanning(n), np.zeros(3 * n)])
    amp = np.abs(np.fft.rfft(xp))
    freqs = np.fft.rfftfreq(4 * n, 1.0 / fs)
    floor = noise_floor(amp, 4 * 31 + 1)
    fm0 = f_sun_nominal * orders["mesh"]
    found = []
    for h in range(1, max_harmonics + 1):
        if h * fm0 * (1 + search) > 0.45 * fs:
            break
        p = _peak(freqs, amp, h * fm0 * (1 - search / h), h * fm0 * (1 + search / h)) if h > 1 \
            else _peak(freqs, amp, fm0 * (1 - search), fm0 * (1 + search))
        if p is None:
            continue
        fl = float(np.interp(p[0], freqs, floor))
        level = 20 * np.log10(p[1] / fl)
        if level > 10.0:
            found.append((h, p[0], level))
        if h == 1 and found:
            fm0 = found[0][1]  # later harmonics searched around the refined fundamental
    if not found:
        raise RecordError(
            f"no mesh line stands 10 dB above the noise near {f_sun_nominal * orders['mesh']:.1f} "
            f"Hz (±{100 * search:.0f} %): check the spec's speed (operating.f_sun), the channel, "
            "or pass the speed explicitly"
        )
    h = np.array([f[0] for f in found], dtype=float)
    fm = np.array([f[1] / f[0] for f in found])
    w = h**2 * np.array([f[2] for f in found])
    f_mesh = float(np.sum(w * fm) / np.sum(w))
    std = float(np.std(fm) / np.sqrt(len(fm))) / orders["mesh"] if len(fm) > 1 else 0.0
    # sideband check on the fundamental
    spacing = twin.lp.n_planets * orders["carrier"] * f_mesh / orders["mesh"]
    weak = True
    for s in (-spacing, spacing):
        p = _peak(freqs, amp, f_mesh + s - 0.2 * spacing, f_mesh + s + 0.2 * spacing)
        if p is not None and p[1] > 2.0 * np.interp(p[0], freqs, floor):
            weak = False
    return OperatingPoint(f_mesh / orders["mesh"], f_mesh, std, "spectrum", tuple(found), weak)


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


def estimate_speed_profile(
    record, twin, speed_range: tuple[float, float], *, channel: int | str = 0,
    harmonic: int = 1, bandwidth: float | None = None,
) -> SpeedProfileEstimate:
    """Input-speed profile of a run-up or coast-down (module docstring).

    **Arguments:** `record`; `twin`; `speed_range`: (lowest, highest) input speed in the record
    (Hz); `harmonic`: mesh harmonic tracked; `bandwidth` (orders) of the tracking band (default
    0.4 × the sideband spacing N × carrier order).
    """
    from dtwin.order import mesh_angle, shaft_speed, tacho_angle

    fs = float(record.sample_rate)
    orders = gear_orders(twin)
    if record.tacho is not None and record.tacho_ppr:
        ang = tacho_angle(np.asarray(record.tacho), fs, int(record.tacho_ppr))
        if record.tacho_shaft == "carrier":
            ang = ang / orders["carrier"]
        method = "tacho"
    else:
        bw = bandwidth or 0.4 * twin.lp.n_planets * orders["carrier"]
        ang = mesh_angle(np.asarray(record.channel(channel)), fs, harmonic * orders["mesh"],
                         speed_range, bandwidth=bw)
        method = "mesh_phase"
    speed = shaft_speed(ang, fs)
    t = np.arange(speed.size) / fs
    # fit the angle (smooth) rather than the differentiated speed: theta = 2 pi (a t + b t^2/2)
    a = np.vstack([t, 0.5 * t**2, np.ones_like(t)]).T
    coef, *_ = np.linalg.lstsq(a, ang / (2 * np.pi), rcond=None)
    f0, slope = float(coef[0]), float(coef[1])
    T = record.duration
    line = f0 + slope * t
    return SpeedProfileEstimate(speed, f0, f0 + slope * T, T, float(np.sqrt(np.mean((speed - line) ** 2))), method)
