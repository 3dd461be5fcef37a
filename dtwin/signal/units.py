"""Vibration units: scale factors, integration of acceleration to velocity and displacement,
decibel references, and the ISO 20816 evaluation zones of broadband velocity.

Quantities and the units accepted (spellings such as ``m/s^2``, ``m/s²``, ``um``, ``µm`` are
normalised by :func:`normalise_unit`):

- acceleration: ``m/s^2``, ``mm/s^2``, ``g`` (standard gravity, 1 g = 9.80665 m/s², ISO 80000-3);
- velocity: ``m/s``, ``mm/s``;
- displacement: ``m``, ``mm``, ``um`` (µm).

**Integration** (:func:`convert_signal`) is done in the frequency domain: the spectrum of the
signal is divided by ``j 2 pi f`` (once for velocity, twice for displacement) and multiplied by
the magnitude of a Butterworth high-pass of order `highpass_order` at `highpass_hz`,
``|H(f)| = 1 / sqrt(1 + (f_c / f)^(2 n))`` (zero phase), and DC is removed. The high-pass is
what makes the integral finite: without it the 1/f (1/f²) gain lifts the sensor's low-frequency
noise and offset without bound. A sine of amplitude A at frequency f well above the cut-off
becomes a velocity sine of amplitude ``A / (2 pi f)``. The integration assumes the record is
periodic (the FFT's view); the first and last few periods of the lowest frequency kept carry
the wrap-around.

**Decibels** (:func:`db_reference`): levels in dB are ``20 log10(a / a_ref)`` with the
reference values of ISO 1683:2015 for SI units (1 µm/s², 1 nm/s, 1 pm) and 1 of the unit
otherwise (``dB re 1 g``, ``dB re 1 V``).

**ISO 20816 zones** (:func:`iso20816_zones`, :func:`iso20816_zone`): ISO 20816-1:2016 evaluates a
machine by the broadband RMS of the velocity measured on its bearing housings (10–1000 Hz for
machines above 600 r/min, 2–1000 Hz from 120 to 600 r/min) against zone boundaries A/B, B/C and
C/D; the numbers are machine-specific and given in the other parts. The values here are those
of ISO 20816-3:2022, Annex A (industrial machines above 15 kW, 120–30 000 r/min, the values of
the former ISO 10816-3 Tables A.1 and A.2):

=========================================  ======  ======  ======
group, support                              A/B     B/C     C/D
=========================================  ======  ======  ======
group 1 (300 kW – 50 MW), rigid             2.3     4.5     7.1
group 1 (300 kW – 50 MW), flexible          3.5     7.1     11.0
group 2 (15 kW – 300 kW), rigid             1.4     2.8     4.5
group 2 (15 kW – 300 kW), flexible          2.3     4.5     7.1
=========================================  ======  ======  ======

(mm/s RMS). Zone A: newly commissioned machines; B: unrestricted long-term operation; C: not
suitable for long-term continuous operation; D: severe enough to cause damage. They apply to the
housing vibration of the machine train (motor, bearings); gear units proper have their own part
(ISO 20816-9, formerly ISO 8579-2), whose values are not reproduced here, so for a gearbox the
zone lines are an orientation, not an acceptance criterion. Reference: ISO 20816-1:2016
"Mechanical vibration — Measurement and evaluation of machine vibration — Part 1: General
guidelines"; ISO 20816-3:2022 "— Part 3: Industrial machinery with a power rating above 15 kW
and operating speeds between 120 r/min and 30 000 r/min".
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import RecordError

__all__ = [
    "G",
    "ISO20816Zones",
    "UNITS",
    "UNSTATED_UNIT",
    "broadband_velocity_rms",
    "convert_signal",
    "convert_spectrum",
    "db_reference",
    "iso20816_zone",
    "iso20816_zones",
    "normalise_unit",
    "quantity",
    "to_db",
    "unit_name",
]

#: Standard gravity (m/s²), ISO 80000-3 / CGPM 1901: 1 g = 9.80665 m/s².
G = 9.80665

#: unit → (quantity, factor to SI: value_SI = value × factor, display text)
UNITS: dict[str, tuple[str, float, str]] = {
    "m/s^2": ("acceleration", 1.0, "m/s²"),
    "mm/s^2": ("acceleration", 1e-3, "mm/s²"),
    "g": ("acceleration", G, "g"),
    "m/s": ("velocity", 1.0, "m/s"),
    "mm/s": ("velocity", 1e-3, "mm/s"),
    "m": ("displacement", 1.0, "m"),
    "mm": ("displacement", 1e-3, "mm"),
    "um": ("displacement", 1e-6, "µm"),
}

_ORDER = {"displacement": 0, "velocity": 1, "acceleration": 2}

#: ISO 1683:2015 reference values (SI) of the level in dB.
_DB_REF_SI = {"acceleration": (1e-6, "1 µm/s²"), "velocity": (1e-9, "1 nm/s"),
              "displacement": (1e-12, "1 pm")}


_ALIASES = {"m/s2": "m/s^2", "m/s/s": "m/s^2", "ms^-2": "m/s^2", "m.s^-2": "m/s^2",
            "mm/s2": "mm/s^2", "G": "g", "gn": "g", "g0": "g", "micron": "um", "microns": "um",
            "ums": "um"}


def normalise_unit(unit: str | None) -> str | None:
    """The canonical spelling of a vibration unit (``m/s²`` → ``m/s^2``, ``µm`` → ``um``,
    ``G`` → ``g``), or None when `unit` is not one of :data:`UNITS` (volts, pascals, "-")."""
    if unit is None:
        return None
    u = unit.strip().replace(" ", "").replace("²", "^2").replace("**2", "^2")
    u = u.replace("µ", "u").replace("μ", "u")
    u = _ALIASES.get(u, u)
    return u if u in UNITS else None


def quantity(unit: str | None) -> str | None:
    """``"acceleration"``, ``"velocity"``, ``"displacement"`` or None for other units."""
    u = normalise_unit(unit)
    return None if u is None else UNITS[u][0]


def _check(unit: str, what: str) -> str:
    u = normalise_unit(unit)
    if u is None:
        raise RecordError(f"{what} unit {unit!r} is not a vibration unit; use one of "
                          f"{', '.join(UNITS)}")
    return u


def _highpass_gain(f: np.ndarray, highpass_hz: float, order: int) -> np.ndarray:
    with np.errstate(divide="ignore"):
        g = 1.0 / np.sqrt(1.0 + (highpass_hz / np.where(f > 0, f, np.inf)) ** (2 * order))
    return np.where(f > 0, g, 0.0)


def convert_spectrum(
    freqs: np.ndarray, amplitude: np.ndarray, from_unit: str, to_unit: str, *,
    highpass_hz: float = 10.0, highpass_order: int = 4,
) -> np.ndarray:
    """Convert an amplitude spectrum between units, integrating or differentiating by ``2 pi f``
    per step between quantities (module docstring), with the same high-pass as
    :func:`convert_signal` when integrating. Amplitudes only (no phase).

    **Arguments:** `freqs` (Hz), `amplitude` (`from_unit`), `from_unit`, `to_unit`
    (:data:`UNITS`), `highpass_hz`, `highpass_order`. **Returns:** the amplitudes in `to_unit`.
    """
    fu, tu = _check(from_unit, "input"), _check(to_unit, "output")
    a = np.asarray(amplitude, dtype=np.float64) * UNITS[fu][1]
    steps = _ORDER[UNITS[fu][0]] - _ORDER[UNITS[tu][0]]
    f = np.asarray(freqs, dtype=np.float64)
    if steps > 0:
        with np.errstate(divide="ignore"):
            w = np.where(f > 0, 1.0 / (2 * np.pi * np.where(f > 0, f, 1.0)), 0.0)
        a = a * w**steps * _highpass_gain(f, highpass_hz, highpass_order)
    elif steps < 0:
        a = a * (2 * np.pi * f) ** (-steps)
    return a / UNITS[tu][1]


def convert_signal(
    x: np.ndarray, sample_rate: float, from_unit: str, to_unit: str, *,
    highpass_hz: float = 10.0, highpass_order: int = 4,
) -> np.ndarray:
    """Convert a time signal between vibration units; acceleration → velocity → displacement by
    integration in the frequency domain behind a zero-phase Butterworth high-pass (module
    docstring); velocity → acceleration by differentiation.

    **Arguments:**

    - `x`: samples (`from_unit`), time on the last axis.
    - `sample_rate`: Hz.
    - `from_unit`, `to_unit`: see :data:`UNITS` (``"g"``, ``"mm/s"``, ``"um"`` …).
    - `highpass_hz`: cut-off of the high-pass applied when integrating (Hz; 10 Hz is the lower
      limit of ISO 20816's broadband range above 600 r/min, 2 Hz below).
    - `highpass_order`: its order (attenuation 6·order dB per octave below the cut-off).

    **Returns:** the signal in `to_unit`, same shape.
    """
    fu, tu = _check(from_unit, "input"), _check(to_unit, "output")
    x = np.asarray(x, dtype=np.float64)
    if UNITS[fu][0] == UNITS[tu][0]:
        return x * (UNITS[fu][1] / UNITS[tu][1])
    if not highpass_hz > 0:
        raise RecordError(f"highpass_hz must be positive (Hz), got {highpass_hz}")
    n = x.shape[-1]
    f = np.fft.rfftfreq(n, 1.0 / float(sample_rate))
    spec = np.fft.rfft(x * UNITS[fu][1], axis=-1)
    steps = _ORDER[UNITS[fu][0]] - _ORDER[UNITS[tu][0]]
    jw = 2j * np.pi * f
    if steps > 0:
        h = np.where(f > 0, 1.0 / np.where(f > 0, jw, 1.0), 0.0) ** steps
        h = h * _highpass_gain(f, highpass_hz, highpass_order)
    else:
        h = jw ** (-steps)
    return np.fft.irfft(spec * h, n=n, axis=-1) / UNITS[tu][1]


#: How a unit the record does not state (None, "" or "-") is written on axes and in dB references.
UNSTATED_UNIT = "record unit"


def unit_name(unit: str | None) -> str:
    """`unit` as written for a reader: :data:`UNSTATED_UNIT` when the record states none."""
    return UNSTATED_UNIT if unit in (None, "", "-") else unit


def db_reference(unit: str | None) -> tuple[float, str]:
    """The reference of levels in dB for `unit`: ``(value in unit, text)``. SI vibration units use
    ISO 1683:2015 (1 µm/s², 1 nm/s, 1 pm, expressed in `unit`); ``g`` uses 1 g; anything else
    1 `unit` (``"1 record unit"`` when the record states none). E.g.
    ``db_reference("mm/s") == (1e-6, "1 nm/s")``."""
    u = normalise_unit(unit)
    if u is None:
        return 1.0, f"1 {unit_name(unit)}"
    q, factor, text = UNITS[u]
    if u == "g":
        return 1.0, "1 g"
    ref_si, ref_text = _DB_REF_SI[q]
    return ref_si / factor, ref_text


def to_db(a: np.ndarray, unit: str | None, *, power: bool = False) -> tuple[np.ndarray, str]:
    """Levels in dB re :func:`db_reference` of `unit`: ``20 log10(a/ref)`` (amplitudes), or
    ``10 log10(a/ref²)`` for powers/PSDs (`power`, per Hz). **Returns:** ``(levels, "dB re …")``,
    zeros mapped to the lowest finite level 300 dB below."""
    ref, text = db_reference(unit)
    a = np.asarray(a, dtype=np.float64)
    if power:
        lv = 10 * np.log10(np.maximum(a, 1e-300) / ref**2)
        return lv, f"dB re ({text})²/Hz"
    return 20 * np.log10(np.maximum(a, 1e-300) / ref), f"dB re {text}"


@dataclasses.dataclass(frozen=True)
class ISO20816Zones:
    """Zone boundaries A/B, B/C, C/D (mm/s RMS, broadband velocity) of one machine class.

    `standard` names the table (module docstring), `group` and `support` the class.
    """

    ab: float
    bc: float
    cd: float
    group: int
    support: str
    standard: str = "ISO 20816-3:2022 Annex A"

    @property
    def boundaries(self) -> dict[str, float]:
        return {"A/B": self.ab, "B/C": self.bc, "C/D": self.cd}

    @property
    def description(self) -> str:
        return (f"{self.standard}, group {self.group} ({'300 kW–50 MW' if self.group == 1 else '15–300 kW'}), "
                f"{self.support} support: A/B {self.ab:g}, B/C {self.bc:g}, C/D {self.cd:g} mm/s RMS")


_ZONES = {(1, "rigid"): (2.3, 4.5, 7.1), (1, "flexible"): (3.5, 7.1, 11.0),
          (2, "rigid"): (1.4, 2.8, 4.5), (2, "flexible"): (2.3, 4.5, 7.1)}


def iso20816_zones(group: int = 2, support: str = "rigid") -> ISO20816Zones:
    """Zone boundaries of ISO 20816-3 Annex A for machine `group` (1: 300 kW–50 MW, 2:
    15–300 kW) on a `support` (``"rigid"`` or ``"flexible"``) foundation (module docstring)."""
    key = (int(group), str(support))
    if key not in _ZONES:
        raise RecordError(f"ISO 20816-3 has groups 1, 2 and supports rigid, flexible; got "
                          f"group {group}, support {support!r}")
    return ISO20816Zones(*_ZONES[key], group=key[0], support=key[1])


def iso20816_zone(velocity_rms_mm_s: float, zones: ISO20816Zones | None = None) -> str:
    """The evaluation zone ``"A"``, ``"B"``, ``"C"`` or ``"D"`` of a broadband velocity RMS
    (mm/s) against `zones` (default group 2, rigid). A value on a boundary lies in the upper
    zone."""
    z = zones or iso20816_zones()
    v = float(velocity_rms_mm_s)
    return "A" if v < z.ab else "B" if v < z.bc else "C" if v < z.cd else "D"


def broadband_velocity_rms(
    x: np.ndarray, sample_rate: float, unit: str, *, band: tuple[float, float] | None = None,
) -> float:
    """Broadband RMS velocity (mm/s) of a vibration signal in ISO 20816-1's band: `band` (Hz),
    default 10–1000 Hz (2–1000 Hz is the band for 120–600 r/min), capped at the Nyquist
    frequency. The velocity spectrum (acceleration divided by ``j 2 pi f``, displacement
    multiplied by it) is summed over the bins inside the band (Parseval), i.e. ideal band
    edges."""
    lo, hi = band or (10.0, 1000.0)
    u = _check(unit, "input")
    q = UNITS[u][0]
    x = np.asarray(x, dtype=np.float64) * UNITS[u][1]
    n = x.shape[-1]
    f = np.fft.rfftfreq(n, 1.0 / float(sample_rate))
    keep = (f >= lo) & (f <= hi) & (f > 0)
    spec = np.fft.rfft(x, axis=-1)[..., keep]
    w = 2 * np.pi * f[keep]
    v = spec / (1j * w) if q == "acceleration" else spec * (1j * w) if q == "displacement" else spec
    weight = np.where(f[keep] == float(sample_rate) / 2, 1.0, 2.0)
    return float(1e3 * np.sqrt(np.sum(weight * np.abs(v) ** 2, axis=-1) / n**2))
