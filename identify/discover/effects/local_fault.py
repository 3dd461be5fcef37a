"""A further local tooth fault (pitting) on the sun, a planet or the ring."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from dtwin.model.faults import Pitting
from dtwin.model.parts.local_fault import LocalFault

from .base import AbstractEffect, EffectParameter, comb_grid

_GROUPS = {"sun": "sun_rotation", "planet": "planet_fault", "ring": "carrier_sidebands"}
_FLANK_TEXT = {"sun": "the flank meeting the sun", "ring": "the flank meeting the ring",
               "both": "both flanks"}


class LocalFaultEffect(AbstractEffect):
    """Pitting of one tooth (severity = fraction of the flank band lost, ≥ 0).

    Part: :class:`dtwin.model.parts.local_fault.LocalFault` of a :class:`dtwin.model.faults.Pitting`
    (stiffness loss linear in the severity). Lines: the impulse comb of the tooth meeting its
    mates (:func:`~dtwin.identify.discover.effects.base.comb_grid`), at low frequency and as mesh
    sidebands: sun ``k fs/N + n fc`` (fm = Zs fs/N: this holds ``m fm + j fs/N + n fc``);
    planet ``k fp + n fc`` (fm = Zp fp), |n| ≤ 2; ring ``k fc`` (fr = N fc, its sidebands and
    the mesh sidebands all lie on the carrier grid: the ring fault belongs to the
    ``carrier_sidebands`` group); k up to what the band holds. Severity bounded to [0, 1] (a
    fit outside is set aside by the search, with the reason in its report).

    A planet tooth meets the sun on one flank and the ring on the other, and which flank a
    fault weakens decides which mesh loses stiffness: a pitted ring flank fitted as a sun-flank
    fault leaves most of its sidebands unexplained. So a planet fault (``flank="fitted"``, the
    default) has one severity per flank, ``planet_fault_sun`` and ``planet_fault_ring``, two
    parts on the same tooth: one flank, the other or both (their sum) is what the fit finds, in
    one candidate. Its main value is the larger of the two. ``flank="sun"``, ``"ring"`` or
    ``"both"`` fixes the flank (one severity, ``planet_fault_<flank>``).
    """

    location: str = eqx.field(static=True, default="sun")
    #: a planet tooth's flank: ``"fitted"`` (one severity per flank, class docstring), ``"sun"``
    #: (the one meeting the sun), ``"ring"`` or ``"both"``; ignored for sun and ring faults
    flank: str = eqx.field(static=True, default="fitted")
    description: ClassVar[str] = "a local tooth fault (pitting)"
    main_name: ClassVar[str] = "pitting severity"
    main_unit: ClassVar[str] = "1"
    typical_range: ClassVar[tuple[float, float]] = (0.05, 0.6)
    typical_note: ClassVar[str] = ("pitting from first visible pits (~5 % of the band) to "
                                   "progressive pitting (~60 %) on inspected industrial gears")

    @property
    def name(self) -> str:
        if self.location == "planet" and self.flank != "fitted":
            return f"planet_local_fault_{self.flank}"
        return f"{self.location}_local_fault"

    @property
    def group(self) -> str:
        return _GROUPS[self.location]

    def _flanks(self) -> tuple[str, ...]:
        """The planet-tooth flanks with a severity each (empty for a sun or ring fault)."""
        if self.location != "planet":
            return ()
        return ("sun", "ring") if self.flank == "fitted" else (self.flank,)

    def parameters(self, twin):
        if self.location != "planet":
            return (EffectParameter(f"{self.location}_fault", "1", 0.1,
                                    f"severity of the {self.location} local fault", (0.0, 1.0),
                                    nonnegative=True),)
        return tuple(EffectParameter(f"planet_fault_{f}", "1", 0.1,
                                     f"severity of the planet local fault on {_FLANK_TEXT[f]}",
                                     (0.0, 1.0), nonnegative=True) for f in self._flanks())

    def parts(self, theta, twin, kin):
        if self.location == "planet":
            return tuple(LocalFault(Pitting(theta[i], location="planet", flank=f))
                         for i, f in enumerate(self._flanks()))
        return (LocalFault(Pitting(theta[0], location=self.location)),)

    def signature(self, kin, f_max):
        if self.location == "sun":
            return comb_grid(kin, f_max, f"fs/{kin.n_planets}", kin.f_sun_fault_per_planet)
        if self.location == "planet":
            return comb_grid(kin, f_max, "fp", kin.f_planet_fault)
        return comb_grid(kin, f_max, "fc", kin.f_carrier, carrier=0, off_carrier_grid=False)

    def main(self, theta):
        """The severity; for a planet fault fitted per flank, that of the worse flank."""
        return jnp.max(theta) if self.location == "planet" and self.flank == "fitted" \
            else theta[0]
