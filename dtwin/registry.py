"""The one registry of parameter names (reference.md §7).

Spec files, the Python API, the CLI (``--free``) and result files all use these names. Each
entry states its SI unit, where it lives in a spec file (a dotted TOML path), a plausible range
(used to catch unit slips when a spec is loaded) and the transform a fit uses to keep it inside
its bounds (``log`` for positive quantities, ``logit`` for quantities inside ``[lower, upper]``,
``none`` for unbounded ones).

Some names are *ties*: ``zeta_mesh`` sets ``zeta_sun_planet`` and ``zeta_ring_planet`` together.
"""

from __future__ import annotations

import dataclasses
import difflib

from .errors import ParameterError


@dataclasses.dataclass(frozen=True)
class ParameterInfo:
    """One registered parameter.

    **Arguments:**

    - `name`: registry name, e.g. ``k_sun_planet``.
    - `unit`: SI unit, e.g. ``N/m``; ``1`` for dimensionless.
    - `description`: one line.
    - `spec_path`: dotted path in a spec file (TOML), e.g. ``mesh.k_sun_planet``.
    - `plausible`: (low, high) range a real planetary gearbox of bench to wind-turbine size lies in;
      values outside are refused at spec load with a hint about units.
    - `transform`: ``log``, ``logit`` or ``none``: how a fit keeps the value inside `bounds`.
    - `bounds`: (lower, upper) hard bounds for fitting.
    - `ties`: names this parameter sets together (empty for ordinary parameters).
    """

    name: str
    unit: str
    description: str
    spec_path: str
    plausible: tuple[float, float]
    transform: str = "log"
    bounds: tuple[float, float] = (0.0, float("inf"))
    ties: tuple[str, ...] = ()


_P = ParameterInfo

_ENTRIES: tuple[ParameterInfo, ...] = (
    # --- meshes -------------------------------------------------------------------------------
    _P("k_sun_planet", "N/m", "mean sun-planet mesh stiffness", "mesh.k_sun_planet", (1e6, 1e11)),
    _P("k_ring_planet", "N/m", "mean ring-planet mesh stiffness", "mesh.k_ring_planet", (1e6, 1e11)),
    _P("zeta_sun_planet", "1", "sun-planet mesh damping ratio", "damping.zeta_sun_planet",
       (0.0, 0.5), "logit", (0.0, 0.5)),
    _P("zeta_ring_planet", "1", "ring-planet mesh damping ratio", "damping.zeta_ring_planet",
       (0.0, 0.5), "logit", (0.0, 0.5)),
    _P("zeta_mesh", "1", "damping ratio of both meshes (tie)", "damping.zeta_mesh",
       (0.0, 0.5), "logit", (0.0, 0.5), ties=("zeta_sun_planet", "zeta_ring_planet")),
    _P("te_amplitude", "m", "static transmission-error amplitude (both meshes)",
       "mesh.te_amplitude", (0.0, 2e-4), "logit", (0.0, 2e-4)),
    # --- supports -----------------------------------------------------------------------------
    _P("k_bearing_sun", "N/m", "sun bearing translational stiffness", "supports.k_bearing_sun",
       (1e5, 1e11)),
    _P("k_bearing_ring", "N/m", "ring support translational stiffness", "supports.k_bearing_ring",
       (1e5, 1e11)),
    _P("k_bearing_carrier", "N/m", "carrier bearing translational stiffness",
       "supports.k_bearing_carrier", (1e5, 1e11)),
    _P("k_bearing_planet", "N/m", "planet bearing translational stiffness",
       "supports.k_bearing_planet", (1e5, 1e11)),
    _P("k_torsion_ring", "N*m/rad", "ring torsional support stiffness", "supports.k_torsion_ring",
       (1e3, 1e10)),
    _P("zeta_support", "1", "support damping ratio", "damping.zeta_support", (0.0, 0.5), "logit",
       (0.0, 0.5)),
    # --- lumped inertias (override geometry) ----------------------------------------------------
    _P("m_sun", "kg", "sun mass", "lumped.m_sun", (1e-3, 1e4)),
    _P("m_ring", "kg", "ring mass", "lumped.m_ring", (1e-3, 1e5)),
    _P("m_carrier", "kg", "carrier mass", "lumped.m_carrier", (1e-3, 1e5)),
    _P("m_planet", "kg", "planet mass", "lumped.m_planet", (1e-3, 1e4)),
    _P("J_sun", "kg*m^2", "sun polar moment of inertia", "lumped.J_sun", (1e-7, 1e4)),
    _P("J_ring", "kg*m^2", "ring polar moment of inertia", "lumped.J_ring", (1e-7, 1e5)),
    _P("J_carrier", "kg*m^2", "carrier polar moment of inertia (with output)",
       "lumped.J_carrier", (1e-7, 1e5)),
    _P("J_planet", "kg*m^2", "planet polar moment of inertia", "lumped.J_planet", (1e-7, 1e4)),
    # --- faults -------------------------------------------------------------------------------
    _P("sun_fault", "1", "severity of the sun local fault", "faults.sun.severity", (0.0, 1.0),
       "logit", (0.0, 1.0)),
    _P("planet_fault", "1", "severity of the planet local fault", "faults.planet.severity",
       (0.0, 1.0), "logit", (0.0, 1.0)),
    _P("ring_fault", "1", "severity of the ring local fault", "faults.ring.severity", (0.0, 1.0),
       "logit", (0.0, 1.0)),
    # --- operating point ----------------------------------------------------------------------
    _P("f_sun", "Hz", "input (sun) rotation frequency", "operating.f_sun", (0.01, 500.0)),
    _P("load_torque", "N*m", "load torque at the carrier (output)", "operating.load_torque",
       (0.0, 1e7)),
    # --- sensor -------------------------------------------------------------------------------
    _P("sensor_gain", "1", "gain of the transfer path to the sensor", "sensor.gain", (1e-6, 1e6)),
)

REGISTRY: dict[str, ParameterInfo] = {e.name: e for e in _ENTRIES}


def register(info: ParameterInfo) -> ParameterInfo:
    """Add a parameter (e.g. of a motor or an effect part). Names must be new."""
    if info.name in REGISTRY and REGISTRY[info.name] != info:
        raise ValueError(f"parameter {info.name!r} is already registered differently")
    REGISTRY[info.name] = info
    return info


def lookup(name: str) -> ParameterInfo:
    """The registry entry of `name`; an unknown name raises `ParameterError` with suggestions."""
    try:
        return REGISTRY[name]
    except KeyError:
        close = difflib.get_close_matches(name, REGISTRY, n=3)
        hint = f" Did you mean {', '.join(close)}?" if close else ""
        raise ParameterError(
            f"unknown parameter {name!r}.{hint} Known parameters: {', '.join(sorted(REGISTRY))}"
        ) from None


def names() -> list[str]:
    """All registered parameter names, sorted."""
    return sorted(REGISTRY)
