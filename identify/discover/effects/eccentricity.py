"""Sun and carrier eccentricity (run-out), each as two linear components."""

from __future__ import annotations

import math
from typing import ClassVar

import jax.numpy as jnp

from dtwin.model.parts.imperfections import CarrierEccentricity, SunEccentricity

from .base import AbstractEffect, EffectParameter, carrier_grid, family_grid, rms


def _components(prefix: str, body: str):
    return (EffectParameter(f"{prefix}_x", "m", 1e-7, f"{body} eccentricity, component at phase 0"),
            EffectParameter(f"{prefix}_y", "m", 1e-7, f"{body} eccentricity, component at phase "
                                                     "pi/2"))


class SunEccentricityEffect(AbstractEffect):
    """Sun run-out turning with the sun: ``e (cos phi, sin phi) = (e_x, e_y)`` (m).

    Part: two :class:`dtwin.model.parts.imperfections.SunEccentricity` (phase 0 and π/2), linear in
    ``(e_x, e_y)``. The mesh excitation turns at ``fsr − fc = fs/N`` in the carrier frame, so
    lines ``m fm ± fs/N + n fc`` — the sun-fault family (look-alike group ``sun_rotation``; a
    local fault adds the higher harmonics of fs/N, a pure run-out only the first).
    """

    name: ClassVar[str] = "sun_eccentricity"
    group: ClassVar[str] = "sun_rotation"
    description: ClassVar[str] = "sun eccentricity / run-out"
    main_name: ClassVar[str] = "sun eccentricity"
    main_unit: ClassVar[str] = "m"
    typical_range: ClassVar[tuple[float, float]] = (1e-7, 3e-5)
    typical_note: ClassVar[str] = (
        "total run-out of small gears 5–30 µm (ISO 1328-2 Fr, grades 5–8); a floating sun "
        "absorbs most of it, the meshes of a stiff (torsional) model see it in full — 0.1 µm "
        "upward is visible")

    def parameters(self, twin):
        return _components("sun_eccentricity", "sun")

    def parts(self, theta, twin, kin):
        return (SunEccentricity(theta[0], jnp.zeros(())),
                SunEccentricity(theta[1], jnp.asarray(math.pi / 2)))

    def signature(self, kin, f_max):
        return family_grid(kin, f_max, f"fs/{kin.n_planets}", kin.f_sun_fault_per_planet,
                           (-1, 1), carrier=3)

    def main(self, theta):
        return rms(theta)


class CarrierEccentricityEffect(AbstractEffect):
    """Carrier eccentricity: all pins offset by ``(e_x, e_y)`` (m) in the carrier frame.

    Part: two :class:`dtwin.model.parts.imperfections.CarrierEccentricity`. Static in the carrier
    frame: each planet's meshes get a different clearance (unequal load sharing) — the same
    forbidden ``m fm + n fc`` lines (group ``carrier_sidebands``).
    """

    name: ClassVar[str] = "carrier_eccentricity"
    group: ClassVar[str] = "carrier_sidebands"
    description: ClassVar[str] = "carrier eccentricity"
    main_name: ClassVar[str] = "carrier eccentricity"
    main_unit: ClassVar[str] = "m"
    typical_range: ClassVar[tuple[float, float]] = (1e-7, 5e-5)
    typical_note: ClassVar[str] = ("carrier bore/pin-circle eccentricity 5–50 µm on industrial "
                                   "carriers; the meshes see the part not absorbed by floating "
                                   "members")

    def parameters(self, twin):
        return _components("carrier_eccentricity", "carrier")

    def parts(self, theta, twin, kin):
        return (CarrierEccentricity(theta[0], jnp.zeros(())),
                CarrierEccentricity(theta[1], jnp.asarray(math.pi / 2)))

    def signature(self, kin, f_max):
        return carrier_grid(kin, f_max)

    def main(self, theta):
        return rms(theta)
