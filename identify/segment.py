"""Fit windows: the stretch of a long record that a fit uses, at the rate the fit needs.

A fit simulates the twin over its whole observation at the record's rate
(:func:`dtwin.identify.residuals.observe`), so its cost grows with the record: 60 s at 25.6 kHz
is minutes of ODE solving per evaluation, while the spectra a fit compares need far less.

- **Length.** The carrier sidebands must be resolved: at least ``MIN_SIDEBAND_BINS / f_c``
  (2 carrier periods, :mod:`dtwin.identify.residuals`); the default window is
  ``max(4 s, 20 / f_c)`` (20 carrier periods; 4 s as the bundled bench records), so the
  sidebands are 20 DFT bins apart and their levels average over several planet passes.
- **Rate.** The fit compares bands ``h f_mesh ± sidebands × N f_c`` below 0.45 × the rate
  (:class:`dtwin.identify.residuals.Features`); for ``harmonics`` mesh harmonics (default 4)
  the record is decimated by the largest integer ``q`` that keeps
  ``harmonics × f_mesh + sidebands × N f_c <= 0.45 × rate / q`` at 1.1 × the input speed.
  The low-pass before decimating is the twin's own anti-aliasing filter at ``q``-fold
  oversampling (:func:`dtwin.simulation.simulate.daq_filter`: Kaiser FIR, cut-off 0.4 of the output rate,
  zero phase here), so measured and simulated spectra pass the same filter. A tachometer is
  kept as the maximum of each ``q`` samples (no pulse is lost; its times move by < q samples).
- **Place.** Default: the steadiest window: the input speed per second of record (from the
  tachometer's pulses, else from the mesh line's frequency), and the window whose speeds spread
  least (``(max - min) / mean``; the earliest of those within 0.05 % of the least).
  ``START:LENGTH`` (s) chooses it.

A record no longer than the window is returned as it is (no cut, no decimation): such fits
behave exactly as without a window. ``FitWindow(whole=True)`` (``--fit-window full``) fits the
whole record at its own rate.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from dtwin.errors import RecordError, SettingsError
from dtwin.model.kinematics import Kinematics
from dtwin.signal.order import tacho_times
from dtwin.simulation.simulate import daq_filter
from dtwin.spec import load_spec

from .operating_point import resolve_speed
from .residuals import MIN_SIDEBAND_BINS

__all__ = ["DEFAULT_HARMONICS", "FitWindow", "Segment", "default_length", "decimation_for_fit",
           "segment_for_fit"]

#: Mesh harmonics a windowed fit keeps below 0.45 × its rate (module docstring).
DEFAULT_HARMONICS = 4
#: Shortest default window (s) and carrier periods in it.
MIN_WINDOW_S, WINDOW_CARRIER_PERIODS = 4.0, 20.0
_SIDEBANDS = 4.0  # Features.sidebands (planet-pass spacings either side of each harmonic)
_SPEED_MARGIN = 1.1  # the rate serves speeds up to 1.1 × the estimated one
_BLOCK_S = 1.0  # speed samples: one per second of record


@dataclasses.dataclass(frozen=True)
class FitWindow:
    """What ``--fit-window`` asks for: `start` and `length` (s; None: chosen as in the module
    docstring), or `whole`: the whole record at its own rate."""

    start: float | None = None
    length: float | None = None
    whole: bool = False

    @classmethod
    def parse(cls, text: str | None) -> FitWindow:
        """``auto`` (or None), ``full``, or ``START:LENGTH`` in seconds (``START`` >= 0,
        ``LENGTH`` > 0). **Raises:** `SettingsError` saying what to write."""
        if text is None or str(text).strip().lower() in ("", "auto"):
            return cls()
        t = str(text).strip().lower()
        if t in ("full", "whole"):
            return cls(whole=True)
        start, sep, length = t.partition(":")
        try:
            s, n = float(start), float(length)
        except ValueError:
            s = n = math.nan
        if not sep or not (math.isfinite(s) and math.isfinite(n)):
            raise SettingsError(f"fit window {text!r}: write START:LENGTH in seconds (e.g. "
                                "10:4), 'auto' (the steadiest stretch) or 'full'")
        if s < 0 or n <= 0:
            raise SettingsError(f"fit window {text!r}: START must be >= 0 s and LENGTH > 0 s")
        return cls(start=s, length=n)

    def text(self) -> str:
        if self.whole:
            return "full"
        if self.start is None:
            return "auto"
        return f"{self.start:g}:{self.length:g}"


@dataclasses.dataclass(frozen=True)
class Segment:
    """The record a fit gets and where it came from.

    - `record`: the stretch (a new record; the input is not modified), or the input itself.
    - `start`, `length`, `record_duration` (s); `sample_rate`, `record_rate` (Hz);
      `decimation` (``q``: record rate / fit rate).
    - `chosen`: ``steadiest``, ``given``, ``start`` (no speed to judge by), ``whole record``.
    - `speed_spread`: ``(max - min) / mean`` of the input speed per second within the window
      (None when not measured).
    """

    record: Any
    start: float
    length: float
    record_duration: float
    sample_rate: float
    record_rate: float
    decimation: int
    chosen: str
    speed_spread: float | None = None

    @property
    def windowed(self) -> bool:
        """Whether the fit sees less than the whole record at its own rate."""
        return self.length < self.record_duration or self.decimation > 1

    def describe(self) -> str:
        """One line for the report: ``fitted on 4.0 s of 60.0 s (from 12.0 s, the steadiest),
        decimated to 5120 Hz``."""
        if not self.windowed:
            return (f"fitted on the whole record ({self.record_duration:.1f} s at "
                    f"{self.record_rate:g} Hz)")
        where = {"steadiest": ", the steadiest", "given": ", as given",
                 "start": ", no speed to choose by"}.get(self.chosen, "")
        spread = (f"; input speed within {100 * self.speed_spread:.2g} %"
                  if self.speed_spread is not None else "")
        rate = (f", decimated to {self.sample_rate:g} Hz" if self.decimation > 1
                else f" at {self.sample_rate:g} Hz")
        return (f"fitted on {self.length:.1f} s of {self.record_duration:.1f} s (from "
                f"{self.start:.1f} s{where}{spread}){rate}")

    def to_dict(self) -> dict[str, Any]:
        return {"start_s": self.start, "length_s": self.length,
                "record_duration_s": self.record_duration, "sample_rate_hz": self.sample_rate,
                "record_rate_hz": self.record_rate, "decimation": self.decimation,
                "chosen": self.chosen, "speed_spread": self.speed_spread,
                "text": self.describe()}


def default_length(f_carrier: float | None) -> float:
    """``max(4 s, 20 / f_carrier)`` (s): the default window (module docstring)."""
    if f_carrier is None or not f_carrier > 0:
        return MIN_WINDOW_S
    return max(MIN_WINDOW_S, WINDOW_CARRIER_PERIODS / float(f_carrier))


def decimation_for_fit(sample_rate: float, kin: Kinematics,
                       harmonics: int = DEFAULT_HARMONICS) -> int:
    """The largest integer ``q`` such that `harmonics` mesh harmonics and their sideband bands
    stay below 0.45 × ``sample_rate / q`` at 1.1 × the input speed of `kin` (module
    docstring); at least 1."""
    top = _SPEED_MARGIN * (harmonics * kin.f_mesh + _SIDEBANDS * kin.f_planet_pass)
    return max(1, int(math.floor(0.45 * float(sample_rate) / top)))


def _gear_set(spec_or_twin):
    """Tooth numbers and planets from a spec (or its path), a twin or a gear set."""
    if isinstance(spec_or_twin, (str, Path)):

        spec_or_twin = load_spec(spec_or_twin)
    if hasattr(spec_or_twin, "gear_set"):
        return spec_or_twin.gear_set()
    if hasattr(spec_or_twin, "lp"):
        return spec_or_twin.lp
    return spec_or_twin


def _tacho_block_speeds(record, kin_orders: dict[str, float], block: int) -> np.ndarray | None:
    """Input speed (Hz) per block of `block` samples from the tachometer's pulses (None without
    one, or with too few pulses)."""
    if record.tacho is None or not record.tacho_ppr:
        return None
    try:
        times = tacho_times(np.asarray(record.tacho), record.sample_rate)
    except RecordError:
        return None
    if times.size < 3:
        return None
    mid = 0.5 * (times[1:] + times[:-1])
    speed = 1.0 / (int(record.tacho_ppr) * np.diff(times))
    if record.tacho_shaft == "carrier":
        speed = speed / kin_orders["carrier"]
    n_blocks = record.n_samples // block
    edges = np.arange(n_blocks + 1) * block / record.sample_rate
    idx = np.clip(np.searchsorted(edges, mid, side="right") - 1, 0, n_blocks - 1)
    total = np.bincount(idx, weights=speed, minlength=n_blocks)
    count = np.bincount(idx, minlength=n_blocks)
    with np.errstate(invalid="ignore"):
        out = total / count
    if np.any(count == 0):  # blocks between two pulses: the interval that spans them
        out[count == 0] = np.interp(0.5 * (edges[:-1] + edges[1:])[count == 0], mid, speed)
    return out


def _mesh_block_speeds(x: np.ndarray, fs: float, mesh_order: float, f_nominal: float,
                       block: int) -> np.ndarray:
    """Input speed (Hz) per block from the strongest line within ±15 % of the mesh frequency
    (Hann, 4-fold zero padding, parabolic interpolation of the log amplitude)."""
    n_blocks = x.size // block
    frames = x[: n_blocks * block].reshape(n_blocks, block)
    frames = (frames - frames.mean(axis=1, keepdims=True)) * np.hanning(block)
    amp = np.abs(np.fft.rfft(frames, n=4 * block, axis=1))
    freqs = np.fft.rfftfreq(4 * block, 1.0 / fs)
    f0 = mesh_order * f_nominal
    lo, hi = np.searchsorted(freqs, [0.85 * f0, 1.15 * f0])
    hi = max(min(hi, freqs.size - 1), lo + 3)
    la = np.log(amp[:, lo:hi] + 1e-300)
    k = np.clip(np.argmax(la, axis=1), 1, la.shape[1] - 2)
    r = np.arange(n_blocks)
    a, b, c = la[r, k - 1], la[r, k], la[r, k + 1]
    den = a - 2 * b + c
    shift = np.where(den < 0, 0.5 * (a - c) / np.where(den < 0, den, -1.0), 0.0)
    return (freqs[lo + k] + shift * (freqs[1] - freqs[0])) / mesh_order


#: Speed spreads closer than this to the least count as equal (0.05 %: a DFT bin at the mesh
#: frequency of a 4 s window at 500 Hz); the earliest such window is taken.
_EQUAL_SPREAD = 5e-4


def _steadiest(speeds: np.ndarray, blocks_per_window: int) -> tuple[int, float]:
    """First block of the earliest window of `blocks_per_window` blocks whose speeds spread
    least (within ``_EQUAL_SPREAD``), and that spread ``(max - min) / mean``."""
    w = min(blocks_per_window, speeds.size)
    win = np.lib.stride_tricks.sliding_window_view(speeds, w)
    spread = (win.max(axis=1) - win.min(axis=1)) / np.abs(win.mean(axis=1))
    spread = np.where(np.isfinite(spread), spread, np.inf)
    i = int(np.flatnonzero(spread <= spread.min() + _EQUAL_SPREAD)[0])
    return i, float(spread[i])


def _decimate(x: np.ndarray, i0: int, i1: int, q: int) -> np.ndarray:
    """Samples ``x[i0:i1]`` low-passed by ``daq_filter(q)`` (zero phase: centred taps; the
    record's samples around the stretch feed the filter, reflected at the record's ends) and
    every `q`-th kept, from ``x[i0]``."""
    taps = daq_filter(q)
    half = (taps.size - 1) // 2
    a, b = max(0, i0 - half), min(x.size, i1 + half)
    ext = np.pad(x[a:b], (half - (i0 - a), half - (b - i1)), mode="reflect")
    return np.convolve(ext, taps, mode="valid")[::q]


def segment_for_fit(record, spec_or_twin, f_sun: float | None = None,
                    window: FitWindow | str | None = None, *, channel: int | str = 0,
                    harmonics: int = DEFAULT_HARMONICS) -> Segment:
    """The stretch of `record` a fit uses (module docstring).

    **Arguments:** `record` (`dtwin.io.Record`); `spec_or_twin`: the gearbox (a spec, its
    path, a twin or a gear set: tooth numbers); `f_sun` (Hz): the input speed if known (else
    the tachometer's, the record's ``metadata["f_sun"]`` or the spec's ``operating.f_sun``:
    :func:`dtwin.identify.operating_point.resolve_speed` without the spectrum estimate);
    `window`: a :class:`FitWindow` or its text (``auto``, ``full``, ``START:LENGTH``);
    `channel`: the fitted channel (speeds without a tachometer); `harmonics`: mesh harmonics
    the decimated rate keeps.

    **Returns:** a :class:`Segment`. **Raises:** `SettingsError` for a window outside the
    record or shorter than the carrier sidebands need.
    """
    win = window if isinstance(window, FitWindow) else FitWindow.parse(window)
    fs = float(record.sample_rate)
    duration = record.n_samples / fs
    whole = Segment(record, 0.0, duration, duration, fs, fs, 1, "whole record")
    if win.whole:
        return whole
    gs = _gear_set(spec_or_twin)
    orders = Kinematics.from_gear_set(gs, 1.0).orders()
    block = max(1, int(round(_BLOCK_S * fs)))
    tacho_speeds = _tacho_block_speeds(record, orders, block) if record.n_samples >= 2 * block \
        else None
    # the speed the window's length and rate follow: given, tachometer, metadata or nominal
    # (no spectrum estimate: the record may be steady only in part)
    op = resolve_speed(record, spec_or_twin, f_sun, channel=channel, estimate=False,
                       check=False, required=False)
    kin = Kinematics.from_gear_set(gs, op.f_sun) if op is not None else None
    f_c = kin.f_carrier if kin is not None else None
    length = win.length if win.length is not None else default_length(f_c)
    if f_c is not None and length < MIN_SIDEBAND_BINS / f_c:
        raise SettingsError(f"fit window of {length:g} s is shorter than the carrier sidebands "
                            f"need ({MIN_SIDEBAND_BINS:g} / f_carrier = "
                            f"{MIN_SIDEBAND_BINS / f_c:.3g} s at f_carrier = {f_c:.2f} Hz); "
                            "lengthen it")
    if win.start is not None and win.start + length > duration * (1 + 1e-9):
        raise SettingsError(f"fit window {win.text()} s reaches past the record's end "
                            f"({duration:.3g} s); move or shorten it")
    if win.start is None and length >= duration:
        return whole  # the record is no longer than the window: as it is
    q = decimation_for_fit(fs, kin, harmonics) if kin is not None else 1
    n_len = int(round(length * fs))
    chosen, spread = "given", None
    if win.start is not None:
        i0 = int(round(win.start * fs))
    else:
        speeds = tacho_speeds
        if speeds is None and kin is not None and record.n_samples >= 2 * block:
            speeds = _mesh_block_speeds(np.asarray(record.channel(channel), dtype=np.float64),
                                        fs, orders["mesh"], kin.f_sun, block)
        if speeds is not None and speeds.size:
            first, spread = _steadiest(speeds, int(math.ceil(length / _BLOCK_S)))
            i0, chosen = min(first * block, record.n_samples - n_len), "steadiest"
        else:
            i0, chosen = 0, "start"
    i0 = max(0, min(i0, record.n_samples - n_len))
    i1 = i0 + n_len
    data = np.stack([_decimate(np.asarray(row, dtype=np.float64), i0, i1, q) if q > 1
                     else np.asarray(row[i0:i1], dtype=np.float64) for row in record.data])
    tacho = None
    if record.tacho is not None:
        t = np.asarray(record.tacho, dtype=np.float64)[i0:i1]
        n_out = data.shape[1]
        if q > 1:
            t = np.pad(t, (0, n_out * q - t.size), mode="edge")
            tacho = t.reshape(n_out, q).max(axis=1)
        else:
            tacho = t.copy()
    seg = Segment(None, i0 / fs, n_len / fs, duration, fs / q, fs, q, chosen, spread)
    meta = {**record.metadata, "fit_window": seg.to_dict()}
    rec = dataclasses.replace(record, data=data, sample_rate=fs / q, tacho=tacho,
                              metadata=meta)
    return dataclasses.replace(seg, record=rec)
