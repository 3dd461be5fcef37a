"""Periodic steady state at constant speed: the gear set's period, the sensor signal's hunting
period and the tiled sampling grid.

At constant input speed every excitation of the twin is a function of the gears' relative
positions: the mesh stiffness and transmission error of each planet's meshes repeat every mesh
cycle; a local fault on the sun repeats when the sun is back in the same place relative to the
carrier (`Zs` mesh cycles), one on the ring or the planet-pass window of a sensor on the ring
when the carrier is back relative to the ring (`Zr` mesh cycles), one on a planet when the
planet is back relative to the carrier (`Zp` mesh cycles). The sensor signal therefore repeats
after the **hunting period**

    T = lcm(Zs, Zr[, Zp]) / f_mesh,   f_mesh = Zr f_carrier = Zr Zs f_sun / (Zs + Zr),

with `Zp` included only when a part depends on a planet's own angle (a planet fault, a planet
bearing defect; not when its severity or amplitude is a concrete zero, as in discovery's
extended model at θ = 0). A motor's torque ripple depends on the sun's angle only. Over `T`
the sun turns `lcm · (Zs + Zr) / (Zs Zr)` times and the carrier
`lcm / Zr` times, both integers, so the shaft angles are back modulo 2π as well
(:func:`shaft_turns`). For the paper's 21/30/81 gearbox at 30 Hz, `T = 567 / 500.3 Hz = 1.13 s`;
with a planet fault on 21/31/84,
`T = 2604 / 504 Hz = 5.17 s`.

The **gear set's** state repeats much sooner (:func:`mechanical_cycles`): the twin's equations
are written in the carrier's frame, where nothing depends on the carrier's absolute angle, so
only the parts' own periods count — one mesh cycle for a healthy gearbox, `Zs` cycles with a
sun fault (21 cycles, 0.042 s, on the paper's gearbox at 30 Hz, against its 1.13 s hunting
period), `Zp` with a planet fault (31 cycles, 0.062 s on 21/31/84). After that period the state
is the same up to the rigid rotation, a fraction of a turn of each shaft
(:func:`rigid_advance`). The planet-pass window that lengthens the signal's period acts after
the gear set: a sensor path's states filter the windowed mesh forces one way
(`dtwin.model.parts.transfer_path.AbstractTransferPath.output_only`).

A record of a constant-speed run after the start-up transient is then the periodic response
sampled at the phases ``(t_k - t_ref) mod T``: :func:`fold_times` maps a sampling grid onto one
period, and :func:`tiled_times` also sorts it and gives the permutation back into record order
(`dtwin.simulation.simulate.simulate` with ``SolverOptions(periodic="auto")`` tiles one period of the gear
set, advances each sample by the rigid rotation and filters the sensor paths over the whole
record).

:func:`hunting_cycles` and :func:`mechanical_cycles` know which parts keep the response
periodic; a part they do not know, a drive other than a constant ideal speed source (a motor's
slip makes the speed differ from the set point), a time-varying load (unless its fluctuation's
amplitude is a concrete zero) make the twin not periodic (None, with the reason from
:func:`periodic_reason` or :func:`mechanical_reason`); so does, for the signal's hunting period
only, a mount path's line (:class:`dtwin.model.parts.mount_path.MountPath`, unless both its
amplitudes are concrete zeros), which reaches the sensor without moving the gears.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from ..model.motor.drive import DrivePart, LoadPart
from ..model.motor.loads import ConstantLoad, FluctuatingLoad
from ..model.motor.shaft import concrete_float
from ..model.motor.speed_source import IdealSpeedSource
from ..model.motor.torque_ripple import TorqueRipple
from ..model.parts.bearing_defect import PlanetBearingDefect
from ..model.parts.imperfections import (
    CarrierEccentricity,
    MeshOffsets,
    PlanetPositionErrors,
    SunEccentricity,
    TransmissionError,
)
from ..model.parts.local_fault import LocalFault
from ..model.parts.mesh_excitation import MeshExcitation
from ..model.parts.mount_path import MountPath
from ..model.parts.supports import Supports
from ..model.parts.transfer_path import AbstractTransferPath

__all__ = ["fold_times", "hunting_cycles", "hunting_period", "mechanical_cycles",
           "mechanical_period", "mechanical_reason", "periodic_reason", "rigid_advance",
           "shaft_turns", "tiled_times"]


def _lcm(*ns: int) -> int:
    out = 1
    for n in ns:
        out = out * int(n) // math.gcd(out, int(n))
    return out


def _concretely_zero(x) -> bool:
    """Whether `x` is a concrete zero (an inert part: a fault of severity 0, a fluctuation of
    amplitude 0); False for tracers, whose value is not known here."""
    if x is None:
        return False
    v = concrete_float(x)
    return v is not None and v == 0.0


def _constant_in_time(load) -> bool:
    """A fluctuating load whose amplitude is (concretely) zero: constant."""
    return isinstance(load, FluctuatingLoad) and _concretely_zero(load.amplitude)


def _planet_dependence(twin, signal: bool = True) -> tuple[bool, str | None]:
    """(whether a part depends on a planet's own angle, reason the twin is not periodic).
    With ``signal=False`` only the gear set's periodicity counts: a mount path's line, which
    reaches the sensor without moving the gears, does not break it."""
    # parts whose forces depend on the mesh phases, the sun or carrier angle only
    angle_only = (Supports, MeshExcitation, AbstractTransferPath, PlanetPositionErrors,
                  SunEccentricity, CarrierEccentricity, MeshOffsets, TransmissionError,
                  TorqueRipple)
    planet = False
    drives = 0
    for p in twin.parts:
        if isinstance(p, DrivePart):
            drives += 1
            if not isinstance(p.drive, IdealSpeedSource):
                return planet, (f"drive {type(p.drive).__name__}: a motor's speed differs from "
                                "its set point (slip, control), the period is not known")
            if p.drive.speed.kind != "constant":
                return planet, f"speed profile {p.drive.speed.kind!r} is not constant"
        elif isinstance(p, LoadPart):
            if not (isinstance(p.load, ConstantLoad) or _constant_in_time(p.load)):
                return planet, f"load {type(p.load).__name__} varies in time"
        elif isinstance(p, LocalFault):
            inert = _concretely_zero(getattr(p.fault, "severity", None))
            planet = planet or (p.fault.location == "planet" and not inert)
        elif isinstance(p, PlanetBearingDefect):
            if _concretely_zero(p.amplitude):
                continue  # no defect: depends on nothing
            if float(p.defect_order) != int(p.defect_order) or (
                    float(p.modulation_order) != int(p.modulation_order)):
                return planet, "planet bearing defect of non-integer order"
            planet = True
        elif isinstance(p, MountPath):
            if signal and not (_concretely_zero(p.a_cos) and _concretely_zero(p.a_sin)):
                return planet, f"mount path line at {p.f:g} Hz varies in time"
        elif not isinstance(p, angle_only):
            return planet, f"part {type(p).__name__} is not known to be periodic"
    if drives == 0:
        return planet, "no drive part"
    return planet, None


def periodic_reason(twin) -> str | None:
    """Why `twin`'s response at constant speed is not (known to be) periodic; None when it is."""
    return _planet_dependence(twin)[1]


def hunting_cycles(twin) -> int | None:
    """Mesh cycles of the hunting period: ``lcm(Zs, Zr)``, times what `Zp` adds when a part
    depends on a planet's own angle; None when the twin is not periodic (:func:`periodic_reason`)."""
    planet, reason = _planet_dependence(twin)
    if reason is not None:
        return None
    lp = twin.lp
    zs, zr, zp = int(lp.z_sun), int(lp.z_ring), int(lp.z_planet)
    return _lcm(zs, zr, zp) if planet else _lcm(zs, zr)


def _part_cycles(p, zs: int, zr: int, zp: int) -> int:
    """Mesh cycles after which part `p`'s forces on the gear set repeat at constant speed
    (0 for a part that is not known to repeat); an output-only transfer path repeats every
    cycle as far as the gear set is concerned."""
    if isinstance(p, (Supports, MeshExcitation, PlanetPositionErrors, CarrierEccentricity,
                      MeshOffsets, TransmissionError, DrivePart, LoadPart, MountPath)):
        return 1
    if isinstance(p, AbstractTransferPath):
        return 1 if p.output_only else 0
    if isinstance(p, SunEccentricity):
        return 1 if _concretely_zero(p.e) else zs
    if isinstance(p, LocalFault):
        if _concretely_zero(getattr(p.fault, "severity", None)):
            return 1
        return {"sun": zs, "ring": zr, "planet": zp}.get(p.fault.location, 0)
    if isinstance(p, PlanetBearingDefect):
        return 1 if _concretely_zero(p.amplitude) else zp
    if isinstance(p, TorqueRipple):
        # the electrical angle h p theta_s: the sun turns (Zs + Zr) / (Zs Zr) per mesh cycle
        order = int(p.harmonic) * int(p.pole_pairs)
        return zs * zr // math.gcd(zs * zr, order * (zs + zr))
    return 0


def mechanical_cycles(twin) -> int | None:
    """Mesh cycles after which the **gear set's** state repeats at constant speed, up to the
    rigid rotation (:func:`rigid_advance`): the least common multiple of its parts' periods —
    1 for the meshes, supports and static imperfections, `Zs` for a sun fault or run-out, `Zr`
    for a ring fault, `Zp` for a planet fault or bearing defect, a whole number of electrical
    turns for a torque ripple. Shorter than :func:`hunting_cycles` (by up to `Zr` times):
    the planet-pass window of a sensor on the housing, whose period is a carrier turn, acts
    after the gear set (the transfer paths' own states are one-way filters of the gear set's
    forces, `AbstractTransferPath.output_only`). None when the gear set is not periodic or a
    part's period is not known (:func:`mechanical_reason`)."""
    if mechanical_reason(twin) is not None:
        return None
    lp = twin.lp
    zs, zr, zp = int(lp.z_sun), int(lp.z_ring), int(lp.z_planet)
    return _lcm(*(_part_cycles(p, zs, zr, zp) for p in twin.parts))


def mechanical_reason(twin) -> str | None:
    """Why the gear set's state at constant speed is not (known to be) periodic
    (:func:`mechanical_cycles`); None when it is."""
    why = _planet_dependence(twin, signal=False)[1]
    if why is not None:
        return why
    lp = twin.lp
    zs, zr, zp = int(lp.z_sun), int(lp.z_ring), int(lp.z_planet)
    for p in twin.parts:
        if _part_cycles(p, zs, zr, zp) == 0:
            if isinstance(p, AbstractTransferPath):
                return (f"transfer path {type(p).__name__}'s states are not a filter of the "
                        "gear set's motion alone")
            return f"part {type(p).__name__} has no known period"
    return None


def mechanical_period(twin, f_sun=None):
    """:func:`mechanical_cycles` in seconds at input speed `f_sun` (Hz; default the drive's
    constant set point, may be traced); None when the twin is not periodic."""
    return _seconds(twin, mechanical_cycles(twin), f_sun)


def _seconds(twin, cycles, f_sun):
    """`cycles` mesh cycles in seconds at `f_sun` (Hz; None: the drive's constant set point);
    None for None cycles."""
    if cycles is None:
        return None
    if f_sun is None:
        drive = next(p.drive for p in twin.parts if isinstance(p, DrivePart))
        f_sun = drive.speed.final / (2.0 * jnp.pi)
    return cycles / mesh_frequency(twin, f_sun)


def rigid_advance(twin, cycles) -> tuple[float, float]:
    """Angles ``(sun, carrier)`` (rad) that the shafts turn in `cycles` mesh cycles at constant
    speed: ``2 pi cycles (Zs + Zr) / (Zs Zr)`` and ``2 pi cycles / Zr``. Independent of the
    speed; whole turns over a hunting period (:func:`shaft_turns`), fractions of a turn over a
    :func:`mechanical_cycles` period. `cycles` may be a JAX value (then so are the angles)."""
    lp = twin.lp
    zs, zr = int(lp.z_sun), int(lp.z_ring)
    return 2.0 * math.pi * cycles * (zs + zr) / (zs * zr), 2.0 * math.pi * cycles / zr


def mesh_frequency(twin, f_sun):
    """Mesh frequency (Hz) at input speed `f_sun` (Hz; may be traced): ``Zr f_sun / (1 + Zr/Zs)``."""
    lp = twin.lp
    return f_sun * lp.z_ring / (1.0 + lp.z_ring / lp.z_sun)


def hunting_period(twin, f_sun=None):
    """Hunting period (s) at input speed `f_sun` (Hz; default: the drive's constant set point,
    may be traced); None when the twin is not periodic."""
    return _seconds(twin, hunting_cycles(twin), f_sun)


def shaft_turns(twin, cycles: int) -> tuple[int, int]:
    """Whole turns ``(sun, carrier)`` over `cycles` mesh cycles (both integers for a hunting
    period): the carrier turns ``cycles / Zr`` times, the sun ``cycles (Zs + Zr) / (Zs Zr)``."""
    lp = twin.lp
    zs, zr = int(lp.z_sun), int(lp.z_ring)
    sun = cycles * (zs + zr) / (zs * zr)
    car = cycles / zr
    if abs(sun - round(sun)) > 1e-9 or abs(car - round(car)) > 1e-9:
        raise ValueError(f"{cycles} mesh cycles are not whole turns of sun and carrier")
    return int(round(sun)), int(round(car))


def fold_times(ts, t_ref, period):
    """Sampling times folded onto one period of the steady state, in their own order.

    **Arguments:** `ts` (s), `t_ref` (s, start of the reference period), `period` (s; may be
    traced).

    **Returns:** ``(mapped, turns)``: times before ``t_ref + period`` kept, later ones
    ``t_ref + (t - t_ref) mod period``, and the whole periods removed from each time (integers
    as floats).
    """
    ts = jnp.asarray(ts)
    late = ts >= t_ref + period
    turns = jnp.where(late, jnp.floor((ts - t_ref) / period), 0.0)
    return ts - turns * period, turns


def tiled_times(ts, t_ref, period):
    """Map sampling times onto one period of the steady state.

    **Arguments:** `ts` (s, nondecreasing), `t_ref` (s, start of the reference period), `period`
    (s; may be traced).

    **Returns:** ``(phase_times, order, inverse, turns)``: times ``t`` before ``t_ref + period``
    are kept, later ones replaced by ``t_ref + (t - t_ref) mod period``; `phase_times` are those
    sorted (a valid `diffrax.SaveAt(ts=...)`), ``phase_times[inverse]`` is the mapped grid in the
    order of `ts`, and `turns` the whole periods removed from each time (integers as floats).
    """
    mapped, turns = fold_times(ts, t_ref, period)
    order = jnp.argsort(mapped)
    inverse = jnp.argsort(order)
    return mapped[order], order, inverse, turns
