"""The drive motor from the spec file's `[motor]` table.

    [motor]
    type = "pmsm"          # "pmsm" (default, the paper's choice) | "induction" | "ideal"
    speed_rpm = 1800.0     # set point at the motor shaft, rpm (synchronous speed for "induction")
    start = "step"         # "step" (paper's STEP from standstill) | "ramp" | "constant" (at speed)
    t_start = 0.0          # s, when the step/ramp begins
    ramp_time = 0.5        # s, for start = "ramp"
    k_shaft = 2000.0       # N·m/rad, shaft + coupling torsional stiffness
    c_shaft = 0.2          # N·m·s/rad, shaft + coupling torsional damping

    [motor.pmsm]           # any of PMSM_DEFAULTS (SI units)
    speed_bandwidth = 20.0
    [motor.induction]      # any of INDUCTION_DEFAULTS, plus supply_frequency (Hz) instead of speed_rpm

Every key is optional; omitted keys take the documented defaults (docs/motor.md): a ~4 kW motor of
the bench's size. The induction drive starts with a 0.5 s V/f ramp unless `start` is given.
Invalid tables raise `SpecError` listing every problem with its field path (`motor.pmsm.L_d`).
The motor parameters that fits may free are registered in :mod:`dtwin.model.registry`: `k_shaft`,
`c_shaft`, `speed_bandwidth`, `current_bandwidth`.
"""

from __future__ import annotations

import difflib
import math
from typing import Any

from ..errors import SpecError
from ..model.motor.drive_base import AbstractDrive
from ..model.motor.induction_motor import INDUCTION_DEFAULTS, InductionMotor
from ..model.motor.pmsm import PMSM, PMSM_DEFAULTS
from ..model.motor.shaft import C_SHAFT_DEFAULT, K_SHAFT_DEFAULT, Shaft
from ..model.motor.speed_source import IdealSpeedSource, SpeedProfile, rpm_to_rad_s
from ..model.registry import ParameterInfo, register

MOTOR_TYPES = ("pmsm", "induction", "ideal")
START_KINDS = ("step", "ramp", "constant")

#: Defaults of the common `[motor]` keys.
MOTOR_DEFAULTS: dict[str, Any] = {
    "type": "pmsm",
    "speed_rpm": 1800.0,
    "start": None,  # "step" for pmsm/ideal, "ramp" for induction
    "t_start": 0.0,
    "ramp_time": 0.5,
    "k_shaft": K_SHAFT_DEFAULT,
    "c_shaft": C_SHAFT_DEFAULT,
}

# Plausible ranges (SI) of a motor of a few hundred W to a few hundred kW: values outside are
# refused with a unit hint, as the registry does for the gearbox parameters.
_PLAUSIBLE: dict[str, tuple[float, float, str]] = {
    "speed_rpm": (0.0, 30000.0, "rpm"),
    "t_start": (0.0, 1e4, "s"),
    "ramp_time": (1e-4, 1e3, "s"),
    "k_shaft": (1.0, 1e8, "N·m/rad"),
    "c_shaft": (0.0, 1e5, "N·m·s/rad"),
    "R_s": (1e-4, 100.0, "ohm"),
    "R_r": (1e-4, 100.0, "ohm"),
    "L_d": (1e-6, 1.0, "H (not mH)"),
    "L_q": (1e-6, 1.0, "H (not mH)"),
    "L_ls": (1e-7, 1.0, "H (not mH)"),
    "L_lr": (1e-7, 1.0, "H (not mH)"),
    "L_m": (1e-5, 20.0, "H (not mH)"),
    "psi_f": (1e-4, 20.0, "Wb = V·s"),
    "pole_pairs": (1, 64, "pole pairs (not poles)"),
    "J_m": (1e-7, 1e4, "kg·m²"),
    "friction": (0.0, 1e3, "N·m·s/rad"),
    "V_dc": (1.0, 1e4, "V"),
    "current_limit": (1e-3, 1e4, "A (peak)"),
    "speed_bandwidth": (0.1, 1e3, "Hz (not rad/s)"),
    "current_bandwidth": (10.0, 2e4, "Hz (not rad/s)"),
    "load_inertia_ratio": (0.0, 1e3, "1"),
    "rated_voltage": (1.0, 2e4, "V line-to-line rms"),
    "rated_frequency": (1.0, 1e3, "Hz"),
    "boost": (0.0, 0.99, "fraction of rated voltage"),
    "supply_frequency": (0.0, 2e3, "Hz"),
}

for _info in (
    ParameterInfo("k_shaft", "N*m/rad", "torsional stiffness of the motor shaft + coupling",
                  "motor.k_shaft", (1.0, 1e8)),
    ParameterInfo("c_shaft", "N*m*s/rad", "torsional damping of the motor shaft + coupling",
                  "motor.c_shaft", (0.0, 1e5)),
    ParameterInfo("speed_bandwidth", "Hz", "bandwidth of the PMSM speed loop",
                  "motor.pmsm.speed_bandwidth", (0.1, 1e3)),
    ParameterInfo("current_bandwidth", "Hz", "bandwidth of the PMSM current loops",
                  "motor.pmsm.current_bandwidth", (10.0, 2e4)),
):
    register(_info)


def _number(value: Any, path: str, problems: list[tuple[str, str]], key: str) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        problems.append((path, f"must be a number, got {value!r}"))
        return None
    x = float(value)
    if not math.isfinite(x):
        problems.append((path, f"must be finite, got {value!r}"))
        return None
    lo, hi, unit = _PLAUSIBLE[key]
    if not lo <= x <= hi:
        problems.append((path, f"{x} is outside the plausible range [{lo}, {hi}] {unit}; check units"))
        return None
    return x


def _unknown(key: str, allowed: list[str], path: str) -> tuple[str, str]:
    close = difflib.get_close_matches(key, allowed, n=2)
    hint = f" Did you mean {' or '.join(close)}?" if close else ""
    return (path, f"unknown key.{hint} Allowed: {', '.join(sorted(allowed))}")


def _sub_table(
    motor_table: dict, name: str, defaults: dict[str, float], extra: tuple[str, ...],
    problems: list[tuple[str, str]],
) -> dict[str, float]:
    sub = motor_table.get(name, {})
    if not isinstance(sub, dict):
        problems.append((f"motor.{name}", f"must be a table, got {sub!r}"))
        return {}
    allowed = list(defaults) + list(extra)
    out: dict[str, float] = {}
    for key, value in sub.items():
        path = f"motor.{name}.{key}"
        if key not in allowed:
            problems.append(_unknown(key, allowed, path))
            continue
        x = _number(value, path, problems, key)
        if x is None:
            continue
        if key == "pole_pairs":
            if x != int(x):
                problems.append((path, f"must be an integer, got {value!r}"))
                continue
        out[key] = x
    return out


def drive_from_spec(motor_table: dict | None) -> AbstractDrive:
    """The drive (motor + controller + shaft) described by a spec's `[motor]` table.

    **Arguments:**

    - `motor_table`: the parsed `[motor]` table (dict; `None` or `{}` for all defaults). Keys and
      defaults: see the module docstring and docs/motor.md.

    **Returns:** a `PMSM`, `InductionMotor` or `IdealSpeedSource` (an `AbstractDrive`).

    **Raises:** `SpecError` listing every invalid key with its path (`motor.pmsm.L_d`) and what
    to change.
    """
    table = {} if motor_table is None else motor_table
    if not isinstance(table, dict):
        raise SpecError([("motor", f"must be a table, got {table!r}")])
    problems: list[tuple[str, str]] = []
    common = dict(MOTOR_DEFAULTS)
    allowed_top = list(MOTOR_DEFAULTS) + ["pmsm", "induction"]
    for key, value in table.items():
        path = f"motor.{key}"
        if key in ("pmsm", "induction"):
            continue
        if key not in allowed_top:
            problems.append(_unknown(key, allowed_top, path))
        elif key == "type":
            if value not in MOTOR_TYPES:
                problems.append((path, f"unknown motor type {value!r}; use one of {', '.join(MOTOR_TYPES)}"))
            else:
                common["type"] = value
        elif key == "start":
            if value not in START_KINDS:
                problems.append((path, f"unknown start {value!r}; use one of {', '.join(START_KINDS)}"))
            else:
                common["start"] = value
        else:
            x = _number(value, path, problems, key)
            if x is not None:
                common[key] = x
    kind = common["type"]
    pmsm = _sub_table(table, "pmsm", PMSM_DEFAULTS, (), problems)
    induction = _sub_table(table, "induction", INDUCTION_DEFAULTS, ("supply_frequency",), problems)

    speed = rpm_to_rad_s(common["speed_rpm"])
    if kind == "induction" and "supply_frequency" in induction:
        p = int(induction.get("pole_pairs", INDUCTION_DEFAULTS["pole_pairs"]))
        from_f = 2.0 * math.pi * induction["supply_frequency"] / p
        if "speed_rpm" in table and abs(from_f - speed) > 1e-9 * max(speed, 1.0):
            problems.append((
                "motor.induction.supply_frequency",
                f"{induction['supply_frequency']} Hz with {p} pole pairs is "
                f"{from_f * 60 / (2 * math.pi):.6g} rpm synchronous, but motor.speed_rpm = "
                f"{common['speed_rpm']}; give only one of them",
            ))
        speed = from_f
    start = common["start"] or ("ramp" if kind == "induction" else "step")
    if problems:
        raise SpecError(problems)

    if start == "step":
        profile = SpeedProfile.step(speed, t_start=common["t_start"])
    elif start == "ramp":
        profile = SpeedProfile.ramp(speed, common["ramp_time"], t_start=common["t_start"])
    else:
        profile = SpeedProfile.constant(speed)
    shaft = Shaft(common["k_shaft"], common["c_shaft"])
    if kind == "ideal":
        return IdealSpeedSource(profile, shaft)
    if kind == "pmsm":
        params = dict(pmsm)
        if "pole_pairs" in params:
            params["pole_pairs"] = int(params["pole_pairs"])
        return PMSM(profile, shaft, **params)  # type: ignore[arg-type]
    params = {k: v for k, v in induction.items() if k != "supply_frequency"}
    if "pole_pairs" in params:
        params["pole_pairs"] = int(params["pole_pairs"])
    return InductionMotor(profile, shaft, **params)  # type: ignore[arg-type]
