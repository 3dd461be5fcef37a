"""Kinematics of a planetary gearbox: its characteristic frequencies, the order bounds of the
combinations that describe a spectral line, and how such a combination is written.

Ring fixed, sun input at ``f_sun`` (Hz), tooth counts ``Zs``, ``Zp``, ``Zr``, ``N`` planets::

    fc = fs Zs / (Zs + Zr)          carrier
    fm = fc Zr = (fs − fc) Zs       mesh
    f_sun_fault    = fm N / Zs      (a sun tooth meets the N planets)
    f_planet_fault = fm / Zp        (one flank; 2 fm / Zp when both flanks strike)
    f_ring_fault   = fm N / Zr = N fc
    fe = p fs                       (electrical frequency of a motor with p pole pairs)

(McFadden & Smith 1985; Zhu, Li & Hu 2022, Eqs. (1)–(4); docs/references.md.)

:class:`Kinematics` is the one type of these frequencies: spectra label their peaks with it
(:func:`dtwin.signal.spectrum.label_frequency`), discovery describes residual lines and builds effect
signatures with it (:mod:`dtwin.identify.lines`, :mod:`dtwin.identify.effects`), and the speed
estimate uses its orders (:func:`dtwin.identify.operating_point.gear_orders`).
:class:`OrderBounds` bounds the combinations searched; :func:`combination_text` writes one
("fm − 7fc").
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Sequence
from typing import Literal

__all__ = ["LABEL_NOTES", "SYMBOLS", "Kinematics", "OrderBounds", "combination_text",
           "symbol_of"]


#: Every frequency symbol a line label may use ("fm − 7fc", "61fsr (comb)", "2fm + fs/3 −
#: fc", "BPFO + fp"): symbol → (what it stands for, the key of :meth:`Kinematics.as_dict` or
#: :attr:`Kinematics.f_electrical` that gives its value in Hz, None where the gearbox alone
#: does not). Ring fixed, sun input; Zs, Zp, Zr tooth counts, N planets. ``fs/N`` stands for
#: every ``fs/<integer>`` ("fs/3" for three planets). The one table the labels are checked
#: against (:func:`combination_text` refuses a symbol it lacks) and that the reports' legends
#: and docs/signal_processing.md ("Symbols of the line labels") are written from.
SYMBOLS: dict[str, tuple[str, str | None]] = {
    "fm": ("mesh frequency, fc·Zr = (fsr − fc)·Zs", "f_mesh"),
    "fc": ("carrier rotation frequency, fsr·Zs/(Zs + Zr)", "f_carrier"),
    "fsr": ("sun (input shaft) rotation frequency, absolute", "f_sun"),
    "fs": ("sun-fault frequency, fm·N/Zs: one sun tooth meeting the N planets", "f_sun_fault"),
    "fs/N": ("the sun fault's repetition per planet, fs/N = fsr − fc (fs/3 for three "
             "planets)", None),
    "fp": ("planet-fault frequency, fm/Zp (the planet's rotation relative to the carrier; "
           "2 fm/Zp when both flanks strike)", "f_planet_fault"),
    "fr": ("ring-fault frequency, fm·N/Zr = N·fc", "f_ring_fault"),
    "N fc": ("planet-pass frequency, N·fc (N planets passing a point of the ring)",
             "f_planet_pass"),
    "fe": ("electrical frequency of the drive motor, pole pairs × fsr", "f_electrical"),
    "fx": ("a modulation frequency located from the record, no gearbox frequency (a load or "
           "speed fluctuation)", None),
    "BPFO": ("ball-pass frequency of a planet bearing's outer race (the planet bore), in the "
             "carrier frame: n fp/2 (1 − d/D cos α), n rolling elements of diameter d on "
             "pitch diameter D, contact angle α", None),
    "BPFI": ("ball-pass frequency of a planet bearing's inner race (the carrier pin), in the "
             "carrier frame: n fp/2 (1 + d/D cos α)", None),
    "BSF": ("ball-spin frequency of a planet bearing's rolling element, D/(2d) fp "
            "(1 − (d/D cos α)²); a rolling-element defect strikes at 2 BSF", None),
    "fcage": ("cage frequency of a planet bearing relative to its pin, fp/2 (1 + d/D cos α)",
              None),
}

#: Words of a line label that are no frequency symbol: annotation → what it says.
LABEL_NOTES: dict[str, str] = {
    "(comb)": ("the line belongs to a comb k·g + n·fc (g one of fs/N, fp, fsr, fe, N fc; k up "
               "to what the band holds) found in the record and scored as one family rather "
               "than line by line"),
    "alias of": ("the line is the mirror 2·(Nyquist frequency) − f of the named line above "
                 "Nyquist, let through the anti-alias filter's transition band"),
    "DC": "0 Hz: every term of the combination cancelled",
}


@dataclasses.dataclass(frozen=True)
class Kinematics:
    """Characteristic frequencies (Hz) at one operating point, ring fixed, sun input.

    Build with :meth:`from_gears` (tooth counts, planets, sun speed, motor pole pairs),
    :meth:`from_gear_set` or :meth:`from_spec`. Constructed directly from frequencies (as the
    spectrum labels are: ``Kinematics(f_mesh, f_carrier, f_sun_fault, f_planet_fault,
    n_planets)``), the fields left None are not used; the tooth counts are then unknown.

    - `f_mesh`, `f_carrier`, `f_sun_fault` (the sun fault's repetition; it enters the labels
      divided by `n_planets`, the paper's "fs/3"), `f_planet_fault`, `n_planets`;
    - `f_sun` (absolute sun rotation), `f_ring_fault`, `f_electrical` (None: no motor line);
    - `z_sun`, `z_planet`, `z_ring`: tooth counts.
    """

    f_mesh: float
    f_carrier: float
    f_sun_fault: float | None = None
    f_planet_fault: float | None = None
    n_planets: int = 3
    f_sun: float | None = None
    f_ring_fault: float | None = None
    f_electrical: float | None = None
    z_sun: int | None = None
    z_planet: int | None = None
    z_ring: int | None = None

    @classmethod
    def from_gears(cls, z_sun: int, z_planet: int, z_ring: int, n_planets: int, f_sun: float,
                   pole_pairs: int | None = None, *,
                   planet_fault: Literal["paper", "both_flanks"] = "paper") -> Kinematics:
        """The closed forms of the module docstring; `planet_fault` ``"both_flanks"`` doubles
        the planet-fault frequency."""
        if planet_fault not in ("paper", "both_flanks"):
            raise ValueError(f"planet_fault must be 'paper' or 'both_flanks', got {planet_fault!r}")
        f_sun = float(f_sun)
        if not (math.isfinite(f_sun) and f_sun > 0):
            raise ValueError(f"f_sun must be a positive frequency in Hz, got {f_sun!r}")
        zs, zp, zr, n = int(z_sun), int(z_planet), int(z_ring), int(n_planets)
        fc = f_sun * zs / (zs + zr)
        fm = fc * zr
        fe = None if pole_pairs is None else pole_pairs * f_sun
        fp = fm / zp * (2.0 if planet_fault == "both_flanks" else 1.0)
        return cls(fm, fc, fm * n / zs, fp, n, f_sun, fm * n / zr, fe, zs, zp, zr)

    @classmethod
    def from_gear_set(cls, gs, f_sun: float, pole_pairs: int | None = None, *,
                      planet_fault: Literal["paper", "both_flanks"] = "paper") -> Kinematics:
        """From a :class:`dtwin.model.gears.GearSet` (or anything with `z_sun`, `z_planet`,
        `z_ring`, `n_planets`, such as :class:`dtwin.model.lumped.LumpedParameters`)."""
        return cls.from_gears(gs.z_sun, gs.z_planet, gs.z_ring, gs.n_planets, f_sun, pole_pairs,
                              planet_fault=planet_fault)

    @classmethod
    def from_spec(cls, spec, f_sun: float | None = None) -> Kinematics:
        """From a `dtwin.spec.Spec`; `f_sun` (Hz) overrides `operating.f_sun`; the motor's pole
        pairs from ``[motor.pmsm] pole_pairs`` (default 4, dtwin's PMSM default, also for the
        ideal drive, whose electrical frequency is then nominal)."""
        g = spec["gears"]
        f = float(spec["operating"]["f_sun"] if f_sun is None else f_sun)
        motor = spec["motor"] or {}
        pp = int((motor.get("pmsm") or {}).get("pole_pairs", 4))
        return cls.from_gears(g["z_sun"], g["z_planet"], g["z_ring"], g["n_planets"], f, pp)

    @property
    def f_sun_fault_per_planet(self) -> float:
        """``f_sun_fault / N`` (the paper's "fs/3" for three planets; = fs − fc)."""
        return self.f_sun_fault / self.n_planets

    @property
    def f_planet_pass(self) -> float:
        """``N fc``: planets passing a point of the ring (Hz)."""
        return self.n_planets * self.f_carrier

    @property
    def f_planet(self) -> float:
        """``fm / Zp``: planet spin relative to the carrier (magnitude, Hz)."""
        return self.f_mesh / self.z_planet

    def orders(self) -> dict[str, float]:
        """Frequencies over the input speed ``f_sun`` (orders): ``mesh``, ``carrier``,
        ``sun_fault``, ``planet_fault``."""
        return {"mesh": self.f_mesh / self.f_sun, "carrier": self.f_carrier / self.f_sun,
                "sun_fault": self.f_sun_fault / self.f_sun,
                "planet_fault": self.f_planet_fault / self.f_sun}

    def as_dict(self) -> dict[str, float]:
        """The characteristic frequencies by name (as :func:`dtwin.model.gears.characteristic_frequencies`)."""
        return {"f_sun": self.f_sun, "f_carrier": self.f_carrier, "f_mesh": self.f_mesh,
                "f_sun_fault": self.f_sun_fault, "f_planet_fault": self.f_planet_fault,
                "f_ring_fault": self.f_ring_fault, "f_planet_pass": self.f_planet_pass,
                "f_planet": self.f_planet}

    def basis(self) -> dict[str, float]:
        """Symbol → frequency (Hz) of the secondary families beside ``fm`` and ``fc``: ``fsr``
        (absolute sun rotation), ``fs/N``, ``fp`` and ``fe``, each only when known."""
        b: dict[str, float] = {}
        if self.f_sun is not None:
            b["fsr"] = self.f_sun
        if self.f_sun_fault is not None:
            b[f"fs/{self.n_planets}"] = self.f_sun_fault_per_planet
        if self.f_planet_fault is not None:
            b["fp"] = self.f_planet_fault
        if self.f_electrical is not None:
            b["fe"] = self.f_electrical
        return b

    def allowed_by_sideband_rule(self, m: int, n: int) -> bool:
        """Whether an ideal gearbox (identical, equally spaced planets) can show ``m fm + n fc``:
        ``(m Zr + n) mod N == 0`` (McFadden & Smith 1985; docs/references.md)."""
        return (m * self.z_ring + n) % self.n_planets == 0


@dataclasses.dataclass(frozen=True)
class OrderBounds:
    """Order bounds of the combinations that describe a line (one type for spectrum labels,
    residual-line descriptions and effect signatures):

    - `mesh`: ``0 <= m <= mesh`` (mesh harmonics);
    - `carrier`: ``|n| <= carrier`` carrier sidebands on the carrier grid ``m fm + n fc``;
    - `fault`: ``|j| <= fault`` orders of a fault family (fs/N, fp; also fsr);
    - `fault_carrier`: ``|n| <= fault_carrier`` carrier sidebands around a fault family line
      (residual-line descriptions; the spectrum labels allow `carrier`);
    - `motor`: ``|j| <= motor`` orders of the electrical frequency.
    """

    mesh: int = 4
    carrier: int = 8
    fault: int = 3
    fault_carrier: int = 2
    motor: int = 6


_MULT = re.compile(r"^(\d+)(\D.*)$")
_FRACTION = re.compile(r"^(\D+)/(\d+)$")


def symbol_of(term: str) -> str:
    """The entry of :data:`SYMBOLS` that a label's term stands on: its multiplier dropped
    ("61fsr" → "fsr") and a fraction's denominator written N ("14fs/3" → "fs/N").

    **Raises:** ``ValueError`` when :data:`SYMBOLS` does not define it: a new symbol needs its
    definition before any label can use it."""
    m = _MULT.match(term)
    sym = m.group(2) if m else term
    f = _FRACTION.match(sym)
    key = f"{f.group(1)}/N" if f else sym
    if key not in SYMBOLS:
        raise ValueError(f"line-label symbol {sym!r} has no definition in "
                         "dtwin.model.kinematics.SYMBOLS: add what it stands for there first")
    return key


def combination_text(terms: Sequence[tuple[str, int]]) -> str:
    """A combination ``sum c_k sym_k`` written like the paper's figures ("fm − 7fc",
    "2fm + fs/3 − fc"), simplified to its shortest equivalent form: like symbols merged (a
    symbol may carry a multiplier, ``("2fm", 1)`` is ``2fm``), whole multiples of a fraction
    written as the symbol (``3fs/3`` is ``fs``), zero terms dropped, terms in
    their first order of appearance; ``"DC"`` when nothing is left. Every symbol must be one
    of :data:`SYMBOLS` (``ValueError`` otherwise, :func:`symbol_of`), so each label a report
    prints has its definition in the report's legend."""
    coef: dict[str, int] = {}
    for sym, c in terms:
        symbol_of(sym)  # every symbol is defined (SYMBOLS)
        m = _MULT.match(sym)
        if m:
            sym, c = m.group(2), int(m.group(1)) * c
        coef[sym] = coef.get(sym, 0) + int(c)
    # a whole multiple of a fraction is the whole symbol: 3·fs/3 → fs, −6·fs/3 → −2fs
    reduced: dict[str, int] = {}
    for sym, c in coef.items():
        f = _FRACTION.match(sym)
        if f and c % int(f.group(2)) == 0:
            sym, c = f.group(1), c // int(f.group(2))
        reduced[sym] = reduced.get(sym, 0) + c
    coef = reduced
    out = ""
    for sym, c in coef.items():
        if c == 0:
            continue
        body = sym if abs(c) == 1 else f"{abs(c)}{sym}"
        if not out:
            out = body if c > 0 else f"−{body}"
        else:
            out += f" + {body}" if c > 0 else f" − {body}"
    return out or "DC"
