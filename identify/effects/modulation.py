"""A load or speed fluctuation at a frequency located from the record (no gearbox frequency)."""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx

from dtwin.parts.drive import LoadPart
from dtwin.parts.loads import FluctuatingLoad
from dtwin.parts.speed_fluctuation import SpeedFluctuation

from ..lines import find_modulation, modulation_lines
from .base import AbstractEffect, EffectParameter, SignatureLine, rms


class LocatedModulationEffect(AbstractEffect):
    """Load torque ``a_cos cos(2 pi f_x t) + a_sin sin(2 pi f_x t)`` (N·m) on the carrier at a
    frequency `f_x` (Hz) located from the record: a fluctuating process load, a brake's
    unevenness or a speed controller's oscillation — anything that modulates the transmitted
    torque at a rate that is not a gearbox frequency.

    Parts: two :class:`dtwin.parts.loads.FluctuatingLoad` (mean 0, active at any speed) and a
    :class:`dtwin.parts.speed_fluctuation.SpeedFluctuation` of the drive's rotor at the same
    frequency, ``b_cos cos(2 pi f_x t) + b_sin sin(2 pi f_x t)`` (rad/s). The load modulates the
    amplitude of every mesh force; the speed fluctuation, which a speed-controlled drive under a
    fluctuating load also makes (its controller's speed dip), modulates the mesh phase, whose
    sidebands grow with the mesh harmonic. Both give the lines ``f_x`` and ``L ± j f_x`` around
    the lines an ideal gearbox has (:func:`dtwin.identify.lines.modulation_lines`), in
    proportions that differ from harmonic to harmonic, so one sensor tells their mix but the
    cause is reported as a "load/speed fluctuation". The main amplitude is the load torque's
    (N·m at the carrier); the speed's is a parameter of its own. `f_x` comes from the data
    (:meth:`adapt`:
    :func:`dtwin.identify.lines.find_modulation`, a family of at least three residual lines
    beside the f_x line, chance ≤ 1e-3); without one the candidate is withdrawn. Group
    ``located_modulation``.
    """

    f_x: float | None = eqx.field(static=True, default=None)
    name: ClassVar[str] = "located_modulation"
    group: ClassVar[str] = "located_modulation"
    description: ClassVar[str] = "load/speed fluctuation at a located frequency"
    main_name: ClassVar[str] = "torque fluctuation amplitude at the carrier"
    main_unit: ClassVar[str] = "N*m"
    typical_range: ClassVar[tuple[float, float]] = (0.2, 10.0)
    typical_note: ClassVar[str] = ("1–20 % of the mean load torque: process-load pulsation, a "
                                   "brake's unevenness, a speed loop's oscillation")

    @property
    def summary(self) -> str:
        """What the step adds, in words ("load/speed fluctuation at 2.10 Hz")."""
        return "load/speed fluctuation" + ("" if self.f_x is None else f" at {self.f_x:.2f} Hz")

    def adapt(self, context):
        if self.f_x is not None:
            return self
        if context.freqs is None or not context.lines:
            return None
        found = context.modulation
        if found is None:
            import dataclasses

            import numpy as np

            freqs = np.asarray(context.freqs)
            df = float(freqs[1] - freqs[0])
            lines = [dataclasses.replace(r, comb="") if "fx" in r.comb else r
                     for r in context.lines]
            found = find_modulation(lines, context.kin, context.tolerance_bins * df,
                                    float(freqs[-1]))
        return None if found is None else LocatedModulationEffect(f_x=found.f_x)

    def parameters(self, twin):
        return (EffectParameter("located_modulation_cos", "N*m", 0.5,
                                "load torque fluctuation at the located frequency, cosine"),
                EffectParameter("located_modulation_sin", "N*m", 0.5,
                                "load torque fluctuation at the located frequency, sine"),
                EffectParameter("located_modulation_speed_cos", "rad/s", 0.05,
                                "rotor speed fluctuation at the located frequency, cosine"),
                EffectParameter("located_modulation_speed_sin", "rad/s", 0.05,
                                "rotor speed fluctuation at the located frequency, sine"))

    def parts(self, theta, twin, kin):
        if self.f_x is None:
            raise ValueError("LocatedModulationEffect needs f_x (adapt() on the data)")
        return (LoadPart(FluctuatingLoad(0.0, theta[0], self.f_x, math.pi / 2,
                                         engage_speed=0.0)),
                LoadPart(FluctuatingLoad(0.0, theta[1], self.f_x, 0.0, engage_speed=0.0)),
                SpeedFluctuation(theta[2], theta[3], self.f_x))

    def signature(self, kin, f_max):
        if self.f_x is None:
            return []
        return [SignatureLine(f, lab) for f, lab in modulation_lines(kin, self.f_x, f_max)]

    def main(self, theta):
        return rms(theta[:2])
