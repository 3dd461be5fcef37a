"""Load-torque fluctuation at an order of the output (carrier) speed."""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx

from dtwin.model.kinematics import combination_text
from dtwin.model.motor.drive import LoadPart
from dtwin.model.motor.loads import FluctuatingLoad

from .base import AbstractEffect, EffectParameter, SignatureLine, carrier_grid, rms


class LoadFluctuationEffect(AbstractEffect):
    """Load torque ``a_cos cos(2 pi h fc t) + a_sin sin(2 pi h fc t)`` (N·m) on the carrier.

    Parts: two :class:`dtwin.model.motor.loads.FluctuatingLoad` (mean 0, active at any speed). A
    misaligned or unbalanced output coupling fluctuates at orders 1–2 of the output speed. All
    planets' forces are modulated together: lines ``allowed ± h fc`` — on the carrier grid,
    look-alike of the planet-to-planet imperfections (group ``carrier_sidebands``), plus the
    low-frequency line ``h fc``.
    """

    order: int = eqx.field(static=True, default=1)
    group: ClassVar[str] = "carrier_sidebands"
    description: ClassVar[str] = "load-torque fluctuation at an order of the output speed"
    main_name: ClassVar[str] = "load fluctuation amplitude"
    main_unit: ClassVar[str] = "N*m"
    typical_range: ClassVar[tuple[float, float]] = (0.2, 10.0)
    typical_note: ClassVar[str] = ("1–20 % of the mean load torque for coupling misalignment "
                                   "or a brake's unevenness (here 50 N·m mean)")

    @property
    def name(self) -> str:
        return f"load_fluctuation_{self.order}fc"

    def parameters(self, twin):
        h = self.order
        return (EffectParameter(f"load_fluctuation_{h}_cos", "N*m", 0.5,
                                f"load torque fluctuation at {h} fc, cosine component"),
                EffectParameter(f"load_fluctuation_{h}_sin", "N*m", 0.5,
                                f"load torque fluctuation at {h} fc, sine component"))

    def parts(self, theta, twin, kin):
        f = self.order * kin.f_carrier
        return (LoadPart(FluctuatingLoad(0.0, theta[0], f, math.pi / 2, engage_speed=0.0)),
                LoadPart(FluctuatingLoad(0.0, theta[1], f, 0.0, engage_speed=0.0)))

    def signature(self, kin, f_max):
        lines = carrier_grid(kin, f_max)
        lines.append(SignatureLine(self.order * kin.f_carrier,
                                   combination_text((("fc", self.order),))))
        return lines

    def main(self, theta):
        return rms(theta)
