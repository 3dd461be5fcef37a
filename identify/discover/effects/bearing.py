"""A local defect in a planet bearing (outer race, inner race or rolling element)."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from dtwin.errors import SettingsError
from dtwin.model.kinematics import combination_text
from dtwin.model.parts.bearing_defect import (
    BEARING_DEFECTS,
    PlanetBearingDefect,
    bearing_frequencies,
)

from .base import AbstractEffect, EffectParameter, SignatureLine

_SYMBOL = {"outer": "BPFO", "inner": "BPFI", "ball": "BSF"}
#: multiples of the symbol per impact (a rolling-element defect strikes at 2 BSF: labels count
#: BSF, so the j-th harmonic reads "2j BSF" — "4BSF", not "22BSF")
_PER_IMPACT = {"outer": 1, "inner": 1, "ball": 2}


class PlanetBearingEffect(AbstractEffect):
    """A defect on one race of a planet bearing (`race`: ``"outer"``, ``"inner"``, ``"ball"``).

    Part: :class:`dtwin.model.parts.bearing_defect.PlanetBearingDefect` on planet 0 (the planets are
    alike up to the phase of the transfer-path window; the spectrum does not tell which one).
    Bearing geometry from the spec's ``[bearings.planet]`` (:meth:`adapt`; without it the
    candidate is withdrawn). Frequencies in the carrier frame, ``f_r = fm / Zp``: BPFO (outer
    race = planet bore, modulated at f_r by the load zone), BPFI (inner race = pin, in the load
    zone, no modulation), 2 BSF (rolling element, modulated at the cage speed relative to the
    pin). Lines
    ``m fm + j f_d + l f_mod + n fc`` (0 ≤ m ≤ 4, 1 ≤ |j| ≤ 4, |l| ≤ 1, |n| ≤ 3): the bearing
    frequencies enter the description through this signature only (its labels), not through
    the order-bound search of :mod:`dtwin.identify.lines`. Each race is its own group
    (``planet_bearing_<race>``): their frequencies differ.
    """

    race: str = eqx.field(static=True, default="outer")
    geometry: tuple | None = eqx.field(static=True, default=None)
    description: ClassVar[str] = "a local defect in a planet bearing"
    main_name: ClassVar[str] = "defect depth (planet drop at an impact)"
    main_unit: ClassVar[str] = "m"
    typical_range: ClassVar[tuple[float, float]] = (2e-8, 5e-6)
    typical_note: ClassVar[str] = (
        "a rolling element dropping into a spall of width b falls ~b²/(4d): 0.1–10 µm for "
        "0.1–1 mm spalls (Sawalhi & Randall 2008); the meshes feel the part not taken by the "
        "pin and the bearing's own compliance — 20 nm upward is visible at the mesh")

    def __check_init__(self):
        if self.race not in BEARING_DEFECTS:
            raise SettingsError(f"PlanetBearingEffect.race must be one of {tuple(BEARING_DEFECTS)}, "
                             f"got {self.race!r}")

    @property
    def name(self) -> str:
        return f"planet_bearing_{self.race}"

    @property
    def group(self) -> str:
        return f"planet_bearing_{self.race}"

    def adapt(self, context):
        bearings = (context.spec["bearings"] if context.spec is not None else None) or {}
        b = bearings.get("planet")
        if not b:
            return None
        geo = (int(b["n_rolling_elements"]), float(b["ball_diameter"]),
               float(b["pitch_diameter"]), float(b.get("contact_angle") or 0.0))
        return PlanetBearingEffect(race=self.race, geometry=geo)

    def orders(self) -> tuple[float, float]:
        """(defect order, modulation order) over the planet's rotation relative to the
        carrier."""
        if self.geometry is None:
            raise SettingsError("PlanetBearingEffect needs the bearing geometry (adapt() with a "
                             "spec that has [bearings.planet])")
        f = bearing_frequencies(*self.geometry)
        d, m = BEARING_DEFECTS[self.race]
        return f[d], (f[m] if m else 0.0)

    def parameters(self, twin):
        return (EffectParameter(f"planet_bearing_{self.race}_depth", "m", 1e-7,
                                f"planet bearing {self.race} defect depth"),)

    def parts(self, theta, twin, kin):
        d, m = self.orders()
        return (PlanetBearingDefect(theta[0], defect_order=d, modulation_order=m),)

    def signature(self, kin, f_max):
        d, m = self.orders()
        f_r = kin.f_planet_fault
        fd, fmod = d * f_r, m * f_r
        sym, msym = _SYMBOL[self.race], ("fp" if self.race == "outer" else "fcage")
        out = []
        for mm in range(0, 5):
            for j in (-4, -3, -2, -1, 1, 2, 3, 4):
                if mm == 0 and j < 0:
                    continue
                for ll in ((-1, 0, 1) if m else (0,)):
                    for n in range(-3, 4):
                        f = mm * kin.f_mesh + j * fd + ll * fmod + n * kin.f_carrier
                        if 0 < f < f_max:
                            out.append(SignatureLine(f, combination_text(
                                (("fm", mm),
                                 (sym, _PER_IMPACT[self.race] * j),
                                 (msym, ll), ("fc", n)))))
        return out

    def main(self, theta):
        return jnp.abs(theta[0])
