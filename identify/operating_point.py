"""The operating point from the data, before any fit: input speed, or its profile in a run-up.

A twin simulated at the nominal 1800 rpm cannot match a bench that turned at 1782 rpm: every
mesh harmonic and sideband would sit in the wrong bins. So the speed is settled first, in one
place (:func:`resolve_speed`), from the first source that has it: a given speed (``--f-sun``) →
the tachometer → the record's metadata → the spectrum estimate → the spec's nominal
``[operating] f_sun``; every speed is checked against :data:`dtwin.simulation.speed_range.F_SUN_MAX`, and a
given, tachometer or metadata speed that the record's lines contradict gets a warning naming
the lines (expected and seen frequencies).

**Spectrum estimate** (:func:`spectrum_speed`). Every gear line of a planetary set with the ring
fixed is a multiple of the carrier frequency: ``m fm + n fc = (m Zr + n) fc``. The estimate
scores, on a grid of speeds within ±`search` (5 %) of the nominal one, the height over the noise
floor (dB, running median) of *every* expected line ``m fm + n fc`` (each mesh harmonic below
``BAND_FRACTION`` × the rate, ``|n| <= SIDEBANDS``), read at its exact frequency on a Hann
spectrum zero-padded ×4 (averaged over 4 s segments on long records). A comb offset by a
sideband (``2fm − fc`` of a speed 1/(2 Zr) higher lands on ``2fm``) catches the lines of one
harmonic at most, and its far sidebands drift off their peaks: the true comb scores higher.
Then each harmonic is searched alone within half a carrier spacing of that comb, its lines
standing ``MIN_LEVEL_DB`` over the floor are interpolated (parabola on the log amplitude), and
its speed is their weighted least-squares fit ``f_k = order_k × f`` (precision of a line ``H``
times its floor in ``T`` s: ``0.5 / (T H)`` Hz). The speed is the weighted mean of the
harmonics', its uncertainty the mean's, widened by their scatter; harmonics that differ by more
than 5 sd and half a bin refuse the estimate (`RecordError`): the record is not steady, or its
lines are not this gearbox's.

**Run-up / coast-down** (:func:`estimate_speed_profile`): the shaft angle from the tachometer, or
a per-frame harmonic-sum speed and a de-chirp refinement, giving the straight line
``f_sun(t) = f0 + (f1 - f0) t / T`` (the twin's ramp set point).
"""

from __future__ import annotations

import dataclasses
import os
import warnings

import numpy as np

from dtwin.errors import RecordError
from dtwin.model.kinematics import Kinematics, combination_text
from dtwin.model.motor.drive import DrivePart
from dtwin.signal.order import shaft_speed, tacho_angle
from dtwin.signal.spectrum import noise_floor
from dtwin.simulation.speed_range import check_input_speed
from dtwin.spec import load_spec

__all__ = ["OperatingPoint", "SpeedCheck", "SpeedDisagreementError", "SpeedLine", "SpeedProfileEstimate",
           "SpeedWarning", "check_speed", "estimate_speed", "estimate_speed_profile",
           "gear_orders", "nominal_speed", "resolve_speed", "spectrum_speed",
           "speed_from_spectrum"]


def gear_orders(twin) -> dict[str, float]:
    """Orders of the input (sun) speed: ``mesh``, ``carrier``, ``sun_fault`` (f / f_sun)."""
    return Kinematics.from_gear_set(twin.lp, 1.0).orders()


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


def _line_label(m: int, n: int) -> str:
    return combination_text([("fm", m), ("fc", n)])


@dataclasses.dataclass(frozen=True)
class SpeedLine:
    """A gear line the spectrum estimate of the speed used.

    - `label` (``"2fm − fc"``), `harmonic` ``m`` and `sideband` ``n``: the line
      ``m fm + n fc``; `order`: its frequency over the input speed;
    - `frequency` (Hz, interpolated peak) and `level_db` (over the local noise floor).
    """

    label: str
    harmonic: int
    sideband: int
    order: float
    frequency: float
    level_db: float

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class OperatingPoint:
    """Input speed of a steady record and where it came from.

    - `f_sun` (Hz), `f_mesh` (Hz); `std_f_sun` (Hz): its standard uncertainty (0 when given
      or from a tachometer);
    - `method`: ``given``, ``tacho``, ``metadata``, ``spectrum`` or ``spec``; `source`: the same
      in words (``--f-sun``, ``tachometer (sun)``, ``record metadata f_sun``, ``mesh lines``,
      ``spec operating.f_sun``);
    - `harmonics`: per mesh harmonic used ``(m, m fm Hz, level dB of its strongest line)``;
      `harmonic_speeds`: per harmonic ``(m, f_sun Hz, sd Hz)``; `lines`: the
      :class:`SpeedLine` s used; `weak`: no carrier sideband among them;
    - `note`: the warning issued with it (the record's lines contradict a given speed, or no
      line was found and the spec's speed is used), else None.
    """

    f_sun: float
    f_mesh: float
    std_f_sun: float
    method: str
    harmonics: tuple[tuple[int, float, float], ...] = ()
    weak: bool = False
    source: str = ""
    lines: tuple[SpeedLine, ...] = ()
    harmonic_speeds: tuple[tuple[int, float, float], ...] = ()
    note: str | None = None

    def to_dict(self) -> dict:
        """JSON-ready: speed, uncertainty, method, source, the lines and per-harmonic speeds."""
        return {"f_sun_hz": self.f_sun, "std_f_sun_hz": self.std_f_sun, "method": self.method,
                "source": self.source, "lines": [ln.to_dict() for ln in self.lines],
                "harmonic_speeds": [{"harmonic": m, "f_sun_hz": f, "sd_hz": s}
                                    for m, f, s in self.harmonic_speeds],
                **({"note": self.note} if self.note else {})}


class SpeedDisagreementError(RecordError):
    """The mesh harmonics of a record put the input speed at different values."""


class SpeedWarning(UserWarning):
    """The record's lines contradict the speed used, or no line was found (the message names
    the lines: expected and seen frequencies)."""


# --- the spectrum estimate ------------------------------------------------------------------

#: Carrier sidebands ``|n|`` scored around each mesh harmonic (at most ``(Zr - 1) / 2``).
SIDEBANDS = 8
#: Weight in the comb score of a line off the sideband rule (not a multiple of N fc).
OFF_RULE_WEIGHT = 0.75
#: A sideband ``n fc`` away from its mesh harmonic weighs ``exp(-n² / 2 SIDEBAND_SPREAD²)``: a
#: mesh harmonic's lines gather around it (the planet-pass window's spectrum).
SIDEBAND_SPREAD = 4.0
#: Top of the band searched, as a fraction of the sampling rate (a DAQ's usable band).
BAND_FRACTION = 0.45
#: The comb scores count a line's height over the floor beyond this (dB): noise rarely reaches
#: it (an amplitude twice the median floor: 6 % of the bins of Gaussian noise).
NOISE_DB = 6.0
#: Cap on a line's height in the joint comb score (dB).
MAX_HEIGHT_DB = 40.0
#: Length (s) of the segments of the comb search's averaged spectrum on long records, at least
#: 16 carrier periods; a record up to twice as long is searched whole.
SEGMENT_S = 4.0
#: A line counts when it stands this far over the local noise floor (dB), and a harmonic when
#: its strongest line stands `HARMONIC_DB` further (Gaussian noise reaches 16 dB over its
#: median with probability ~1e-12 per bin).
MIN_LEVEL_DB = 10.0
HARMONIC_DB = 6.0
#: Frequency precision of an interpolated Hann peak: ``LINE_PRECISION / (T H)`` Hz for a line
#: ``H`` times its noise floor in a record of ``T`` s, at least ``LINE_PRECISION_FLOOR / T``.
LINE_PRECISION = 0.5
LINE_PRECISION_FLOOR = 0.01
#: Each harmonic is searched alone within this many bins (at the harmonic) of the joint comb,
#: at most half a carrier spacing; its lines are read within `LINE_WINDOW_BINS` of the comb.
HARMONIC_WINDOW_BINS = 2.0
LINE_WINDOW_BINS = 0.3
#: Harmonics that disagree with the others refuse the estimate when their lines carry this
#: share of the line height (dB summed over the lines used); fewer are left out.
DISAGREE_SHARE = 0.25
#: Harmonics disagree when their speeds differ by more than this many standard deviations and
#: move the harmonic's line by more than half a bin.
DISAGREE_SIGMA = 5.0


@dataclasses.dataclass(frozen=True)
class _Spectrum:
    freqs: np.ndarray
    amp: np.ndarray
    duration: float  # s: the resolution is 1 / duration


def _hann_spectrum(x: np.ndarray, fs: float, n_seg: int, pad: int) -> _Spectrum:
    """Hann amplitude spectrum, averaged (power) over half-overlapping segments of `n_seg`
    samples, each zero-padded to ``pad × n_seg``."""
    w = np.hanning(n_seg)
    hop = max(1, n_seg // 2)
    power = np.zeros(pad * n_seg // 2 + 1)
    count = 0
    for s in range(0, x.size - n_seg + 1, hop):
        seg = x[s:s + n_seg]
        power += np.abs(np.fft.rfft((seg - seg.mean()) * w, pad * n_seg)) ** 2
        count += 1
    return _Spectrum(np.fft.rfftfreq(pad * n_seg, 1.0 / fs), np.sqrt(power / count), n_seg / fs)


def _loaded(spec_or_twin):
    """A spec given by its path, loaded; anything else as it is."""
    if isinstance(spec_or_twin, (str, os.PathLike)):

        return load_spec(spec_or_twin)
    return spec_or_twin


def _teeth(spec_or_twin) -> tuple[int, int, int] | None:
    """``(z_sun, z_ring, n_planets)`` of a spec (or its path), twin, gear set or
    :class:`~dtwin.model.kinematics.Kinematics`; None without tooth numbers."""
    obj = _loaded(spec_or_twin)
    if obj is None:
        return None
    if hasattr(obj, "gear_set"):
        obj = obj.gear_set()
    elif hasattr(obj, "lp"):
        obj = obj.lp
    zs, zr = getattr(obj, "z_sun", None), getattr(obj, "z_ring", None)
    if zs is None or zr is None:
        return None
    return int(zs), int(zr), int(getattr(obj, "n_planets", 3))


def nominal_speed(spec_or_twin) -> float | None:
    """The nominal input speed (Hz): a spec's ``operating.f_sun``, a twin's drive set point, a
    :class:`~dtwin.model.kinematics.Kinematics`' ``f_sun``; None when it states none."""
    obj = _loaded(spec_or_twin)
    if obj is None:
        return None
    if hasattr(obj, "parts"):

        for p in obj.parts:
            if isinstance(p, DrivePart):
                return float(p.drive.speed.final) / (2 * np.pi)
        return None
    if isinstance(obj, Kinematics):
        return obj.f_sun
    try:
        f = obj["operating"].get("f_sun")
    except (TypeError, KeyError, AttributeError):
        return None
    return float(f) if f else None


class _Comb:
    """The gear lines ``m fm + n fc + j fsr`` (``1 <= m``, ``|n| <= SIDEBANDS``; the sun's
    rotation ``j = ±1`` beside the lines with ``|n| <= 2``) below `f_top` at speeds up to
    `f_high`, and their weights in the comb score."""

    def __init__(self, teeth, f_high: float, f_top: float, max_harmonics: int | None):
        z_sun, z_ring, n_planets = teeth
        self.co = z_sun / (z_sun + z_ring)  # carrier order
        self.mo = self.co * z_ring  # mesh order
        self.z_ring = z_ring
        K = max(1, min(SIDEBANDS, (z_ring - 1) // 2))
        rows = []
        m = 1
        while m * self.mo * f_high <= f_top and (max_harmonics is None or m <= max_harmonics):
            for n in range(-K, K + 1):
                for j in ((-1, 0, 1) if n == 0 else (0,)):
                    if ((m * z_ring + n) * self.co + j) * f_high < f_top:
                        rows.append((m, n, j))
            m += 1
        self.m, self.n, self.j = (np.array(c, dtype=int).reshape(-1) for c in zip(*rows, strict=True)) \
            if rows else (np.zeros(0, dtype=int),) * 3
        self.order = (self.m * z_ring + self.n) * self.co + self.j  # line / f_sun
        # the sideband rule: at a sensor fixed to the ring the planets' contributions add up
        # in the lines at multiples of the planet-pass frequency N fc and largely cancel
        # elsewhere (McFadden & Smith 1985); the other lines, and the sun's rotation
        # sidebands (eccentricity, a sun fault), count at half weight
        on_rule = ((self.m * z_ring + self.n) % n_planets == 0) & (self.j == 0)
        self.weight = np.where(on_rule, 1.0, OFF_RULE_WEIGHT) * np.exp(
            -0.5 * (self.n / SIDEBAND_SPREAD) ** 2)

    @property
    def harmonics(self) -> list[int]:
        return sorted(set(self.m.tolist()))

    def label(self, i: int) -> str:
        return combination_text([("fm", int(self.m[i])), ("fc", int(self.n[i])),
                                 ("fsr", int(self.j[i]))])


def _heights(sp: _Spectrum, pad: int) -> np.ndarray:
    """Line heights: dB over the running-median floor (61 bins) beyond `NOISE_DB`, else 0."""
    floor = noise_floor(sp.amp, pad * 61 + 1)
    return np.maximum(20 * np.log10(np.maximum(sp.amp, 1e-300) / floor) - NOISE_DB, 0.0)


def _comb_search(sp: _Spectrum, height: np.ndarray, orders: np.ndarray, weight: np.ndarray,
                 lo: float, hi: float, step_bins: float) -> float:
    """The speed in [lo, hi] (Hz) whose lines ``orders × f`` collect the most height (times
    `weight`); grid step `step_bins` bins at the highest line, then a tenth of that around the
    best."""
    step = step_bins / (sp.duration * float(orders.max()))
    best, best_score = lo, -np.inf
    for grid in (np.arange(lo, hi + step / 2, step),):
        for i in range(0, grid.size, 2048):
            g = grid[i:i + 2048]
            s = np.interp(g[:, None] * orders[None, :], sp.freqs, height) @ weight
            j = int(np.argmax(s))
            if s[j] > best_score:
                best, best_score = float(g[j]), float(s[j])
    fine = np.linspace(max(lo, best - step), min(hi, best + step), 21)
    s = np.interp(fine[:, None] * orders[None, :], sp.freqs, height) @ weight
    return float(fine[int(np.argmax(s))])


def _line_at(sp: _Spectrum, f: float, half_width: float) -> tuple[float, float] | None:
    """Interpolated peak (Hz) within ``f ± half_width`` and its level over the local floor (dB,
    median of ±30 bins); None without an interior maximum."""
    df = float(sp.freqs[1] - sp.freqs[0])
    i0, i1 = int(np.floor((f - half_width) / df)), int(np.ceil((f + half_width) / df))
    i0, i1 = max(i0, 1), min(i1, sp.amp.size - 2)
    if i1 <= i0:
        return None
    k = i0 + int(np.argmax(sp.amp[i0:i1 + 1]))
    a, b, c = np.log(np.maximum(sp.amp[k - 1:k + 2], 1e-300))
    den = a - 2 * b + c
    if den >= 0 or b < a or b < c:  # not a peak: the flank of a line outside the window
        return None
    d = float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))
    w = int(round(30.0 / (sp.duration * df)))
    floor = float(np.median(sp.amp[max(0, k - w):k + w + 1]))
    peak = float(np.exp(b - 0.25 * (a - c) * d))
    return float(sp.freqs[k] + d * df), 20 * np.log10(peak / max(floor, 1e-300))


def _harmonic_speed(lines: list[SpeedLine], duration: float) -> tuple[float, float, list]:
    """Least-squares speed ``f = sum(o f_k / s_k^2) / sum(o^2 / s_k^2)`` of one harmonic's lines
    (``s_k`` their precision), its sd (inflated by the lines' own scatter), after dropping lines
    more than 5 sd off while three or more remain."""
    lines = list(lines)
    while True:
        o = np.array([ln.order for ln in lines])
        f = np.array([ln.frequency for ln in lines])
        h = 10 ** (np.array([ln.level_db for ln in lines]) / 20)
        s = np.maximum(LINE_PRECISION / (duration * h), LINE_PRECISION_FLOOR / duration)
        wt = o**2 / s**2
        est = float(np.sum(o * f / s**2) / np.sum(wt))
        sd = float(1.0 / np.sqrt(np.sum(wt)))
        z = (f - o * est) / s
        if len(lines) >= 3 and np.max(np.abs(z)) > DISAGREE_SIGMA:
            lines.pop(int(np.argmax(np.abs(z))))
            continue
        if len(lines) >= 2:
            sd *= np.sqrt(max(1.0, float(np.sum(z**2)) / (len(lines) - 1)))
        return est, sd, lines


def spectrum_speed(x: np.ndarray, sample_rate: float, gears, f_centre: float, *,
                   search: float = 0.05, band_fraction: float = BAND_FRACTION,
                   max_harmonics: int | None = None, min_level_db: float = MIN_LEVEL_DB,
                   ) -> OperatingPoint:
    """Input speed (Hz) from a steady signal's gear lines, every mesh harmonic and its carrier
    sidebands jointly (module docstring).

    **Arguments:** `x`: samples; `sample_rate` (Hz); `gears`: tooth numbers (a spec, twin, gear
    set or :class:`~dtwin.model.kinematics.Kinematics`); `f_centre` (Hz): the centre of the search;
    `search`: its relative half-width; `band_fraction`: the band searched ends at this fraction
    of the rate; `max_harmonics`: at most this many mesh harmonics (default: every one in the
    band); `min_level_db`: a line counts this far over the noise floor.

    **Returns:** :class:`OperatingPoint` (``method="spectrum"``) with the lines used and the
    per-harmonic speeds. **Raises:** `RecordError` when no mesh harmonic stands above the noise,
    or when the harmonics disagree (the message gives each one's speed).
    """
    teeth = _teeth(gears)
    if teeth is None:
        raise RecordError("the speed estimate needs the gearbox's tooth numbers (a spec)")
    fs = float(sample_rate)
    x = np.asarray(x, dtype=np.float64)
    if not np.all(np.isfinite(x)):
        raise RecordError("the record holds NaN or inf samples; clean or cut it first")
    f_top = band_fraction * fs
    lo, hi = f_centre * (1 - search), f_centre * (1 + search)
    comb = _Comb(teeth, hi, f_top, max_harmonics)
    if comb.m.size == 0:
        raise RecordError(f"no mesh harmonic lies below {f_top:.0f} Hz ({band_fraction:g} × the "
                          f"rate) at {f_centre:.4g} Hz input speed: record at a higher rate")
    n = x.size
    pad = 4 if n <= 2**20 else 2
    full = _hann_spectrum(x, fs, n, pad)
    seg_n = int(round(fs * max(SEGMENT_S, 16.0 / (comb.co * f_centre))))
    coarse = full if n <= 2 * seg_n else _hann_spectrum(x, fs, seg_n, 4)
    return _comb_speed(full, coarse, 4 if coarse is not full else pad, comb, lo, hi, f_top,
                       min_level_db, f_centre, search)


def speed_from_spectrum(freqs: np.ndarray, amp: np.ndarray, gears, f_centre: float, *,
                        search: float = 0.05, f_top: float | None = None,
                        min_level_db: float = MIN_LEVEL_DB) -> OperatingPoint:
    """:func:`spectrum_speed` on a one-sided Hann amplitude spectrum `amp` at `freqs` (Hz,
    uniform, from 0; resolution ``1 / T``) rather than on the samples; the band searched ends
    at `f_top` (Hz; default ``BAND_FRACTION / 0.5`` × the top frequency)."""
    teeth = _teeth(gears)
    if teeth is None:
        raise RecordError("the speed estimate needs the gearbox's tooth numbers (a spec)")
    freqs = np.asarray(freqs, dtype=np.float64)
    sp = _Spectrum(freqs, np.asarray(amp, dtype=np.float64), 1.0 / float(freqs[1] - freqs[0]))
    f_top = 2 * BAND_FRACTION * float(freqs[-1]) if f_top is None else float(f_top)
    lo, hi = f_centre * (1 - search), f_centre * (1 + search)
    comb = _Comb(teeth, hi, f_top, None)
    if comb.m.size == 0:
        raise RecordError(f"no mesh harmonic lies below {f_top:.0f} Hz at {f_centre:.4g} Hz "
                          "input speed")
    return _comb_speed(sp, sp, 1, comb, lo, hi, f_top, min_level_db, f_centre, search)


def _comb_speed(full: _Spectrum, coarse: _Spectrum, pad: int, comb: _Comb, lo: float,
                hi: float, f_top: float, min_level_db: float, f_centre: float,
                search: float) -> OperatingPoint:
    """The comb estimate on `coarse` (the search) and `full` (the lines), module docstring."""
    height = _heights(coarse, pad)
    # the joint comb: heights capped at MAX_HEIGHT_DB, so that no single line outweighs a comb
    f_joint = _comb_search(coarse, np.minimum(height, MAX_HEIGHT_DB), comb.order, comb.weight,
                           lo, hi, 0.25)
    # each harmonic on its own, near the joint comb
    lines: dict[int, list[SpeedLine]] = {}
    speeds = []
    for m in comb.harmonics:
        idx = np.flatnonzero(comb.m == m)
        half = min(0.5 / (m * comb.z_ring),
                   HARMONIC_WINDOW_BINS / (coarse.duration * m * comb.mo * f_joint))
        f_m0 = _comb_search(coarse, height, comb.order[idx], comb.weight[idx],
                            f_joint * (1 - half), f_joint * (1 + half), 0.1)
        found = []
        for i in idx:
            p = _line_at(full, comb.order[i] * f_m0, LINE_WINDOW_BINS / coarse.duration)
            if p is not None and p[1] >= min_level_db and p[0] < f_top:
                found.append(SpeedLine(comb.label(i), m, int(comb.n[i]), float(comb.order[i]),
                                       *p))
        if not found or max(ln.level_db for ln in found) < min_level_db + HARMONIC_DB:
            continue  # weak peaks in the noise do not make a harmonic
        f_m, sd_m, lines[m] = _harmonic_speed(found, full.duration)
        speeds.append((m, f_m, sd_m))
    if not speeds:
        raise RecordError(
            f"no mesh harmonic stands above the noise near {f_centre * comb.mo:.1f} Hz "
            f"(±{100 * search:.0f} %): check the spec's speed (operating.f_sun) and tooth "
            "numbers, the channel, or pass the speed (--f-sun HZ, or a tachometer: --tacho "
            "CHANNEL)")
    est, sd_est, bad = _combine(speeds, comb.mo, full.duration)
    def evidence(ms):
        return sum(ln.level_db for m in ms for ln in lines[m])

    if bad and evidence([b[0] for b in bad]) >= DISAGREE_SHARE * evidence(lines):
        each = "; ".join(f"{_line_label(m, 0)} and its sidebands at {fm:.4f} ± {s:.2g} Hz"
                         for m, fm, s in speeds)
        raise SpeedDisagreementError(
            f"the mesh harmonics disagree on the input speed ({each}): the record is not "
            "steady, or its lines are not this gearbox's (check the spec's tooth numbers and "
            "the channel); pass the speed (--f-sun HZ, or a tachometer: --tacho CHANNEL)")
    if bad:  # a few weak harmonics off the others' speed (other lines near them): not used
        speeds = [s for s in speeds if s not in bad]
        est, sd_est, _ = _combine(speeds, comb.mo, full.duration)
    used = [ln for m, _, _ in speeds for ln in lines[m]]
    harmonics = tuple((m, m * comb.mo * fm, max(ln.level_db for ln in lines[m]))
                      for m, fm, _ in speeds)
    return OperatingPoint(est, est * comb.mo, sd_est, "spectrum", harmonics,
                          not any(ln.sideband != 0 for ln in used), "mesh lines",
                          tuple(used), tuple(speeds))


def _combine(speeds, mesh_order: float, duration: float):
    """Weighted mean of the harmonics' speeds, its sd (widened by their scatter beyond their
    sds), and the harmonics that disagree with it (more than ``DISAGREE_SIGMA`` sd and half a
    bin at the harmonic)."""
    f = np.array([s[1] for s in speeds])
    sd = np.array([s[2] for s in speeds])
    est = float(np.sum(f / sd**2) / np.sum(1 / sd**2))
    sd_est = float(1 / np.sqrt(np.sum(1 / sd**2)))
    if len(speeds) > 1:
        chi2 = float(np.sum(((f - est) / sd) ** 2))
        sd_est *= float(np.sqrt(max(1.0, chi2 / (len(speeds) - 1))))
    bad = [(m, fm, s) for m, fm, s in speeds
           if abs(fm - est) > DISAGREE_SIGMA * s and abs(fm - est) * m * mesh_order * duration
           > 0.5]
    return est, sd_est, bad


def estimate_speed(
    record, twin, f_sun_nominal: float, *, channel: int | str = 0, search: float = 0.05,
    max_harmonics: int | None = None, min_level_db: float = MIN_LEVEL_DB,
) -> OperatingPoint:
    """Input speed of a steady record: from its tachometer when it has one (the mean speed of
    its pulses), else :func:`spectrum_speed` within ±`search` of `f_sun_nominal` (Hz).

    **Arguments:** `record` (`dtwin.io.Record`); `twin` (tooth numbers: a twin, spec or gear
    set); `f_sun_nominal` (Hz); `channel`; `search`; `max_harmonics`; `min_level_db`.

    **Returns:** :class:`OperatingPoint`.
    """
    tacho = _tacho_speed(record, twin)
    if tacho is not None:
        return tacho
    return spectrum_speed(record.channel(channel), record.sample_rate, twin, f_sun_nominal,
                          search=search, max_harmonics=max_harmonics, min_level_db=min_level_db)


# --- the one resolver -----------------------------------------------------------------------


def _tacho_speed(record, gears) -> OperatingPoint | None:
    """Mean input speed from the record's tachometer (None without one); a carrier tachometer
    needs the tooth numbers."""
    if record is None or getattr(record, "tacho", None) is None or not record.tacho_ppr:
        return None
    fs = float(record.sample_rate)
    ang = tacho_angle(np.asarray(record.tacho, dtype=np.float64), fs, int(record.tacho_ppr))
    f = float((ang[-1] - ang[0]) / (2 * np.pi * (ang.size - 1) / fs))
    shaft = record.tacho_shaft or "sun"
    teeth = _teeth(gears)
    if shaft == "carrier":
        if teeth is None:
            return None
        f = f * (teeth[0] + teeth[1]) / teeth[0]
    mo = teeth[0] * teeth[1] / (teeth[0] + teeth[1]) if teeth else float("nan")
    return OperatingPoint(f, f * mo, 0.0, "tacho", source=f"tachometer ({shaft})")


def _with_tacho(record, tacho):
    """`record` with channel `tacho` (a name or index; ``(channel, ppr, shaft)``) as its
    tachometer."""
    if tacho is None:
        return record
    ch, ppr, shaft = (tacho, 1, "sun") if isinstance(tacho, (str, int)) else tuple(tacho)
    return dataclasses.replace(record, tacho=np.asarray(record.channel(ch), dtype=np.float64),
                               tacho_ppr=int(ppr), tacho_shaft=shaft)


@dataclasses.dataclass(frozen=True)
class SpeedCheck:
    """What the record's lines say about a claimed speed: `f_record` (Hz; None: no mesh line
    found), `agrees`, and `message` naming the lines (expected vs seen) when it does not."""

    f_claim: float
    f_record: float | None
    agrees: bool
    message: str | None
    record_point: OperatingPoint | None = None


def _evidence(op: OperatingPoint) -> float:
    return float(sum(ln.level_db for ln in op.lines))


def check_speed(record, spec_or_twin, f_claim: float, *, channel: int | str = 0,
                what: str = "the given speed", search: float = 0.05) -> SpeedCheck:
    """Check a claimed input speed (Hz) against the record's gear lines.

    The lines are searched within ±`search` of the claim and, when the spec's nominal speed
    lies outside that, of the nominal too; the estimate with more line height is the record's.
    It agrees when it lies within ``4 sd`` of the claim or moves its highest line used by less
    than half a bin. **Returns:** :class:`SpeedCheck`; its message names, per harmonic, the
    strongest line's frequency expected at the claim and seen.
    """
    x = record.channel(channel)
    fs = float(record.sample_rate)
    tries = []
    centres = [f_claim]
    nominal = nominal_speed(spec_or_twin)
    if nominal and abs(nominal / f_claim - 1) > search:
        centres.append(nominal)
    for c in centres:
        try:
            tries.append(spectrum_speed(x, fs, spec_or_twin, c, search=search))
        except RecordError:
            continue
    teeth = _teeth(spec_or_twin)
    mo = teeth[0] * teeth[1] / (teeth[0] + teeth[1])
    if not tries:
        exp = ", ".join(f"{_line_label(m, 0)} at {m * mo * f_claim:.1f} Hz" for m in (1, 2, 3)
                        if m * mo * f_claim < BAND_FRACTION * fs)
        return SpeedCheck(f_claim, None, False,
                          f"{what} {f_claim:g} Hz: the record shows no mesh line where it puts "
                          f"them ({exp or 'above the usable band'}), nor near the spec's speed")
    op = max(tries, key=_evidence)
    o_max = max(ln.order for ln in op.lines)
    tol = max(4 * op.std_f_sun, 0.5 / (record.duration * o_max))
    if abs(op.f_sun - f_claim) <= tol:
        return SpeedCheck(f_claim, op.f_sun, True, None, op)
    best = {}
    for ln in op.lines:
        if ln.harmonic not in best or ln.level_db > best[ln.harmonic].level_db:
            best[ln.harmonic] = ln
    named = "; ".join(f"{ln.label} expected at {ln.order * f_claim:.2f} Hz, seen at "
                      f"{ln.frequency:.2f} Hz ({ln.level_db:.0f} dB over the floor)"
                      for ln in list(best.values())[:4])
    return SpeedCheck(
        f_claim, op.f_sun, False,
        f"{what} {f_claim:g} Hz disagrees with the record's mesh lines, which put the input "
        f"speed at {op.f_sun:.4f} ± {op.std_f_sun:.2g} Hz: {named}", op)


def resolve_speed(record, spec_or_twin=None, given: float | None = None, *,
                  channel: int | str = 0, tacho=None, search: float = 0.05,
                  estimate: bool = True, check: bool = True, fallback: bool = True,
                  required: bool = True) -> OperatingPoint | None:
    """The input (sun) speed of a steady record, from the first source that has one:

    1. `given` (Hz, e.g. ``--f-sun``), checked by :func:`dtwin.simulation.speed_range.check_input_speed`;
    2. the tachometer: `tacho` (a channel of `record`, or ``(channel, ppr, shaft)``) or the
       record's own (:func:`dtwin.signal.order.tacho_angle`, mean over the record);
    3. the record's ``metadata["f_sun"]``;
    4. the spectrum estimate (:func:`spectrum_speed`, around the spec's nominal speed);
    5. the spec's nominal ``[operating] f_sun`` (or the twin's drive set point).

    A speed from 1–3 is checked against the record's lines (:func:`check_speed`, when `check`
    and a gearbox is given); a contradiction is a :class:`SpeedWarning` naming the lines, kept
    in the result's `note`. The spectrum estimate refuses (`RecordError`) when the harmonics
    disagree; when it finds no mesh line, the nominal speed is used with a warning
    (`fallback`) or the `RecordError` is raised (``fallback=False``). `estimate=False` skips 4.

    **Arguments:** `record` (`dtwin.io.Record`, or None: 1 and 5 only); `spec_or_twin`: a spec
    (or its path), twin, gear set (tooth numbers) or None; `channel`: the analysed channel.

    **Returns:** :class:`OperatingPoint`; None when no source gives a speed and not `required`
    (then a `RecordError` saying what to pass).
    """
    teeth = _teeth(spec_or_twin)
    mo = teeth[0] * teeth[1] / (teeth[0] + teeth[1]) if teeth else float("nan")
    if record is not None and tacho is not None:
        record = _with_tacho(record, tacho)
    op = None
    if given is not None:
        f = check_input_speed(given)
        op = OperatingPoint(f, f * mo, 0.0, "given", source="--f-sun")
        what = "--f-sun"
    if op is None and record is not None:
        op = _tacho_speed(record, spec_or_twin)
        if op is not None:
            check_input_speed(op.f_sun, "tachometer")
            what = "the tachometer's speed"
    if op is None and record is not None:
        meta = record.metadata.get("f_sun") if isinstance(record.metadata, dict) else None
        if isinstance(meta, (int, float)) and not isinstance(meta, bool) and meta > 0:
            f = check_input_speed(meta, "record metadata f_sun")
            op = OperatingPoint(f, f * mo, 0.0, "metadata", source="record metadata f_sun")
            what = "the record's metadata f_sun"
    nominal = nominal_speed(spec_or_twin)
    if op is not None:
        if check and teeth is not None and record is not None:
            res = check_speed(record, spec_or_twin, op.f_sun, channel=channel,
                              what=what, search=search)
            if not res.agrees:
                warnings.warn(res.message, SpeedWarning, stacklevel=2)
                op = dataclasses.replace(op, note=res.message)
        return op
    if estimate and record is not None and teeth is not None and nominal:
        try:
            return spectrum_speed(record.channel(channel), record.sample_rate, spec_or_twin,
                                  nominal, search=search)
        except RecordError as e:
            if not fallback or isinstance(e, SpeedDisagreementError):
                raise
            note = f"{e}; the spec's speed ({nominal:g} Hz) is used"
            warnings.warn(note, SpeedWarning, stacklevel=2)
            return OperatingPoint(check_input_speed(nominal, "operating.f_sun"),
                                  nominal * mo, 0.0, "spec", source="spec operating.f_sun",
                                  note=note)
    if nominal:
        f = check_input_speed(nominal, "operating.f_sun")
        return OperatingPoint(f, f * mo, 0.0, "spec", source="spec operating.f_sun")
    if not required:
        return None
    raise RecordError("the input speed is unknown: pass --f-sun HZ, a tachometer channel "
                      "(--tacho CHANNEL), or a spec with operating.f_sun")


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
