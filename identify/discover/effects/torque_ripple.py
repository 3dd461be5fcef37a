"""Motor torque ripple at a harmonic of the electrical frequency."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx

from dtwin.model.kinematics import combination_text
from dtwin.model.motor.torque_ripple import TorqueRipple

from .base import AbstractEffect, EffectParameter, SignatureLine, rms


class TorqueRippleEffect(AbstractEffect):
    """Torque ripple ``a_cos cos(h p theta_s) + a_sin sin(h p theta_s)`` (N·m) on the sun.

    Part: :class:`dtwin.model.motor.torque_ripple.TorqueRipple` (new part). Lines far from fm:
    ``j h fe + m fm + n N fc`` (j = ±1, |n| ≤ 2), fe = p fsr the electrical frequency.
    """

    harmonic: int = eqx.field(static=True, default=6)
    group: ClassVar[str] = "motor"
    description: ClassVar[str] = "motor torque ripple at a harmonic of the electrical frequency"
    main_name: ClassVar[str] = "torque ripple amplitude"
    main_unit: ClassVar[str] = "N*m"
    typical_range: ClassVar[tuple[float, float]] = (0.01, 2.0)
    typical_note: ClassVar[str] = ("servo PMSMs: cogging plus ripple 0.5–5 % of rated torque "
                                   "(datasheets of ~20 N·m motors: 0.1–1 N·m)")

    @property
    def name(self) -> str:
        return f"torque_ripple_{self.harmonic}fe"

    def parameters(self, twin):
        h = self.harmonic
        return (EffectParameter(f"torque_ripple_{h}_cos", "N*m", 0.05,
                                f"torque ripple at {h} fe, cosine component"),
                EffectParameter(f"torque_ripple_{h}_sin", "N*m", 0.05,
                                f"torque ripple at {h} fe, sine component"))

    def parts(self, theta, twin, kin):
        pp = round(kin.f_electrical / kin.f_sun)
        return (TorqueRipple(theta[0], theta[1], pole_pairs=pp, harmonic=self.harmonic),)

    def signature(self, kin, f_max):
        out = []
        g = self.harmonic * kin.f_electrical
        n_pl = kin.n_planets
        for m in range(0, 5):
            for j in (-1, 1):
                for n in range(-2, 3):
                    f = m * kin.f_mesh + j * g + n * n_pl * kin.f_carrier
                    if 0 < f < f_max:
                        out.append(SignatureLine(f, combination_text(
                            (("fm", m), ("fe", j * self.harmonic), ("fc", n * n_pl)))))
        return out

    def main(self, theta):
        return rms(theta)
