"""A load or speed fluctuation at a frequency located from the record (no gearbox frequency)."""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx

from dtwin.model.motor.drive import LoadPart
from dtwin.model.motor.loads import FluctuatingLoad
from dtwin.model.motor.speed_fluctuation import SpeedFluctuation
from dtwin.model.parts.mount_path import MountPath

from ...lines import find_modulation, modulation_lines
from .base import AbstractEffect, EffectParameter, SignatureLine, rms
from .transfer_path import _sensor_path, window_mean


def _flat_path(twin) -> float:
    """Sensor acceleration (m/s²) per N·m of carrier torque fluctuation through a flat path:
    the ring's share ``Zr / (Zs + Zr)`` of the carrier torque as ring-mesh force (base radius),
    seen through the planet-pass window's mean, per ring mass."""
    lp = twin.lp
    path = _sensor_path(twin)
    c0, weight = 1.0, 1.0
    if path is not None:
        c0 = (float(path.window_harmonics[0]) if path.window_harmonics is not None
              else window_mean(float(path.window_exponent)))
        weight = float(path.force_weight)
    zs, zr = float(lp.z_sun), float(lp.z_ring)
    return c0 * weight * zr / (zs + zr) / (float(lp.rb_ring) * float(lp.m_ring))


class LocatedModulationEffect(AbstractEffect):
    """Load torque ``a_cos cos(2 pi f_x t) + a_sin sin(2 pi f_x t)`` (N·m) on the carrier at a
    frequency `f_x` (Hz) located from the record: a fluctuating process load, a brake's
    unevenness or a speed controller's oscillation — anything that modulates the transmitted
    torque at a rate that is not a gearbox frequency.

    Parts: two :class:`dtwin.model.motor.loads.FluctuatingLoad` (mean 0, active at any speed) and a
    :class:`dtwin.model.motor.speed_fluctuation.SpeedFluctuation` of the drive's rotor at the same
    frequency, ``b_cos cos(2 pi f_x t) + b_sin sin(2 pi f_x t)`` (rad/s). The load modulates the
    amplitude of every mesh force; the speed fluctuation, which a speed-controlled drive under a
    fluctuating load also makes (its controller's speed dip), modulates the mesh phase, whose
    sidebands grow with the mesh harmonic. Both give the lines ``f_x`` and ``L ± j f_x`` around
    the lines an ideal gearbox has (:func:`dtwin.identify.lines.modulation_lines`), in
    proportions that differ from harmonic to harmonic, so one sensor tells their mix but the
    cause is reported as a "load/speed fluctuation". The main amplitude is the load torque's
    (N·m at the carrier); the speed's is a parameter of its own.

    The line at ``f_x`` itself lies below the lowest line of a healthy record (the planet-pass
    frequency), where calibration has nothing to fit the path against: the housing rocking on
    its mounts carries it to the sensor with a gain and phase of its own
    (:class:`dtwin.model.parts.mount_path.MountPath`). Its two amplitudes are parameters of their own,
    stated as the torque fluctuation that would give the line through a flat path (the
    planet-pass window's mean, no high-pass: ring-mesh force per ring mass), so the torque's
    estimate rests on the mesh sidebands, which reach the sensor through the calibrated path.
    `f_x` comes from the data
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
                                "rotor speed fluctuation at the located frequency, sine"),
                EffectParameter("located_modulation_mount_cos", "N*m", 0.5,
                                "the f_x line through the housing's mounts, as a torque "
                                "through a flat path, cosine"),
                EffectParameter("located_modulation_mount_sin", "N*m", 0.5,
                                "the f_x line through the housing's mounts, as a torque "
                                "through a flat path, sine"))

    def parts(self, theta, twin, kin):
        if self.f_x is None:
            raise ValueError("LocatedModulationEffect needs f_x (adapt() on the data)")
        k = _flat_path(twin)  # m/s² per N·m through a flat path
        return (LoadPart(FluctuatingLoad(0.0, theta[0], self.f_x, math.pi / 2,
                                         engage_speed=0.0)),
                LoadPart(FluctuatingLoad(0.0, theta[1], self.f_x, 0.0, engage_speed=0.0)),
                SpeedFluctuation(theta[2], theta[3], self.f_x),
                MountPath(k * theta[4], k * theta[5], self.f_x))

    def signature(self, kin, f_max):
        if self.f_x is None:
            return []
        return [SignatureLine(f, lab) for f, lab in modulation_lines(kin, self.f_x, f_max)]

    def main(self, theta):
        return rms(theta[:2])
