"""The one registry of parameter names (docs/references.md §7, docs/conventions.md).

Spec files, the Python API, the CLI (``--free``) and result files all use these names. Each
entry states its SI unit, where it lives in a spec file (a dotted TOML path), where it lives in
a twin (its :mod:`dtwin.model.address`: every reader and writer of a twin's parameters goes through
it), a plausible range (used to catch unit slips when a spec is loaded) and the transform a fit
uses to keep it inside its bounds (``log`` for positive quantities, ``logit`` for quantities
inside ``[lower, upper]``, ``none`` for unbounded ones).

Some names are *ties*: ``zeta_mesh`` sets ``zeta_sun_planet`` and ``zeta_ring_planet`` together.

A new parameter is one entry here (or :func:`register` next to the part that owns it) with its
address; nothing else changes. Parameters that belong to one analysis only (the effects of
discrepancy discovery) stay out of the global table: :class:`RegistryView` overlays them.
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Iterable, Mapping

import jax.numpy as jnp

from ..errors import ParameterError
from .address import AbstractAddress, LumpedField, PartElement, PartField, SignalGain, Tie
from .faults import MissingTooth
from .motor.drive import LoadPart
from .parts.imperfections import CarrierEccentricity, SunEccentricity, TransmissionError
from .parts.local_fault import LocalFault
from .parts.mesh_excitation import MeshExcitation
from .parts.transfer_path import PlanetPassTransferPath, window_cosine_coefficients


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
    - `address`: where it lives in a twin (:mod:`dtwin.model.address`); None when a twin does not
      hold it (the operating speed, estimated from a record; motor-table values).
    """

    name: str
    unit: str
    description: str
    spec_path: str
    plausible: tuple[float, float]
    transform: str = "log"
    bounds: tuple[float, float] = (0.0, float("inf"))
    ties: tuple[str, ...] = ()
    address: AbstractAddress | None = None

    @property
    def section(self) -> str:
        """The spec section it lives in (first part of `spec_path`, e.g. ``mesh``)."""
        return self.spec_path.split(".")[0]

    @property
    def settable(self) -> bool:
        """Whether a fit can write this parameter into a twin."""
        return self.address is not None


def _P(*args, **kw) -> ParameterInfo:
    """An entry; a name that is a field of `LumpedParameters` lives there unless told."""
    info = ParameterInfo(*args, **kw)
    if info.address is None and "address" not in kw:
        try:
            info = dataclasses.replace(info, address=LumpedField(info.name))
        except ParameterError:
            pass
    return info


def _zero_fault(location: str):
    return LocalFault(MissingTooth(0.0, location=location))


def _zero_sun_fault():
    return _zero_fault("sun")


def _zero_planet_fault():
    return _zero_fault("planet")


def _zero_ring_fault():
    return _zero_fault("ring")


def _zero_transmission_error():
    return TransmissionError(jnp.zeros(()))


def _zero_sun_eccentricity():
    return SunEccentricity(jnp.zeros(()))


def _zero_carrier_eccentricity():
    return CarrierEccentricity(jnp.zeros(()))


#: Registered cosine terms of the window and mesh harmonics of the excitation (calibration
#: fits no more than these: every calibrated quantity has a name). Thirteen window terms reach
#: the second planet-pass harmonic ``2 N`` of up to six planets; twelve mesh harmonics are
#: those of the spec's default stiffness waveform (``mesh.n_harmonics``).
N_WINDOW_TERMS = 13
N_EXCITATION_HARMONICS = 12


def _window_fill(path, size: int):
    """The series of the window the path already uses (unchanged dynamics), `size` terms."""
    old = path.window_harmonics
    if old is None:
        return window_cosine_coefficients(float(path.window_exponent), size)
    return jnp.concatenate([old, jnp.zeros(size - old.shape[0])])


def _zeros_fill(_part, size: int):
    return jnp.zeros(size)


def _zero_excitation():
    return MeshExcitation.zeros(N_EXCITATION_HARMONICS)


def _window_entries() -> tuple[ParameterInfo, ...]:
    return tuple(
        _P(f"window_c{k}", "1", f"cosine coefficient {k} of the planet-angle window "
           "(calibrated transfer path)", f"sensor.window_harmonics[{k}]", (-100.0, 100.0),
           "none", (-float("inf"), float("inf")),
           address=PartElement(PlanetPassTransferPath, ("window_harmonics",), k, _window_fill,
                               N_WINDOW_TERMS))
        for k in range(N_WINDOW_TERMS))


def _excitation_entries() -> tuple[ParameterInfo, ...]:
    out = []
    for mesh in ("sun", "ring"):
        for cs in ("cos", "sin"):
            for h in range(1, N_EXCITATION_HARMONICS + 1):
                out.append(_P(
                    f"excitation_{mesh}_{cs}_{h}", "m",
                    f"transmission-error {cs}ine coefficient of mesh harmonic {h}, "
                    f"{mesh}-planet meshes (calibrated excitation)",
                    f"mesh.excitation_{mesh}_{cs}[{h - 1}]", (-1e-3, 1e-3), "none",
                    (-float("inf"), float("inf")),
                    address=PartElement(MeshExcitation, (f"{mesh}_{cs}",), h - 1, _zeros_fill,
                                        N_EXCITATION_HARMONICS, _zero_excitation)))
    return tuple(out)


def _frf_entries() -> tuple[ParameterInfo, ...]:
    # the sensor response belongs to the DAQ, not to the twin: no address (dtwin calibrate
    # solves it in closed form; identify cannot free it)
    return tuple(
        _P(f"frf_db_{j}", "dB", f"gain of the sensor frequency response at knot {j}",
           f"sensor.frf_db[{j}]", (-300.0, 300.0), "none", (-float("inf"), float("inf")))
        for j in range(8))


def _load_share_entries() -> tuple[ParameterInfo, ...]:
    # a share becomes mesh clearances through the twin's static balance (dtwin.spec.build); dtwin
    # calibrate fits the shares, identify cannot free them (no address in the twin)
    return tuple(
        _P(f"load_share_{i}", "1", f"load share of planet {i} relative to planet 0 "
           "(calibrated unequal load sharing)", f"imperfections.load_sharing[{i}]", (0.0, 3.0),
           "none", (0.0, 3.0))
        for i in range(1, 8))


def _fault(location: str, factory) -> PartField:
    return PartField(LocalFault, ("fault", "severity"), (("fault.location", location),), factory)

_ENTRIES: tuple[ParameterInfo, ...] = (
    # --- meshes -------------------------------------------------------------------------------
    _P("k_sun_planet", "N/m", "mean sun-planet mesh stiffness", "mesh.k_sun_planet", (1e6, 1e11)),
    _P("k_ring_planet", "N/m", "mean ring-planet mesh stiffness", "mesh.k_ring_planet", (1e6, 1e11)),
    _P("zeta_sun_planet", "1", "sun-planet mesh damping ratio", "damping.zeta_sun_planet",
       (0.0, 0.5), "logit", (0.0, 0.5)),
    _P("zeta_ring_planet", "1", "ring-planet mesh damping ratio", "damping.zeta_ring_planet",
       (0.0, 0.5), "logit", (0.0, 0.5)),
    _P("zeta_mesh", "1", "damping ratio of both meshes (tie)", "damping.zeta_mesh",
       (0.0, 0.5), "logit", (0.0, 0.5), ties=("zeta_sun_planet", "zeta_ring_planet"),
       address=Tie((LumpedField("zeta_sun_planet"), LumpedField("zeta_ring_planet")))),
    _P("te_amplitude", "m", "static transmission-error amplitude (both meshes)",
       "mesh.te_amplitude", (0.0, 2e-4), "logit", (0.0, 2e-4),
       address=PartField(TransmissionError, ("amplitude",), factory=_zero_transmission_error)),
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
       "logit", (0.0, 1.0), address=_fault("sun", _zero_sun_fault)),
    _P("planet_fault", "1", "severity of the planet local fault", "faults.planet.severity",
       (0.0, 1.0), "logit", (0.0, 1.0), address=_fault("planet", _zero_planet_fault)),
    _P("ring_fault", "1", "severity of the ring local fault", "faults.ring.severity", (0.0, 1.0),
       "logit", (0.0, 1.0), address=_fault("ring", _zero_ring_fault)),
    # --- imperfections ------------------------------------------------------------------------
    _P("sun_eccentricity", "m", "sun run-out (centre offset turning with the sun)",
       "imperfections.sun_eccentricity", (0.0, 1e-3), "logit", (0.0, 1e-3),
       address=PartField(SunEccentricity, ("e",), factory=_zero_sun_eccentricity)),
    _P("carrier_eccentricity", "m", "carrier eccentricity (all pins offset)",
       "imperfections.carrier_eccentricity", (0.0, 1e-3), "logit", (0.0, 1e-3),
       address=PartField(CarrierEccentricity, ("e",), factory=_zero_carrier_eccentricity)),
    # --- operating point ----------------------------------------------------------------------
    _P("f_sun", "Hz", "input (sun) rotation frequency", "operating.f_sun", (0.01, 500.0)),
    _P("load_torque", "N*m", "load torque at the carrier (output)", "operating.load_torque",
       (0.0, 1e7), address=PartField(LoadPart, ("load", "torque_value"))),
    # --- sensor -------------------------------------------------------------------------------
    _P("sensor_gain", "1", "gain of the transfer path to the sensor", "sensor.gain", (1e-6, 1e6),
       address=SignalGain()),
    # --- calibration (dtwin calibrate; docs/calibration.md) -------------------------------------
    *_window_entries(),
    *_excitation_entries(),
    *_frf_entries(),
    *_load_share_entries(),
)

REGISTRY: dict[str, ParameterInfo] = {e.name: e for e in _ENTRIES}


def register(info: ParameterInfo) -> ParameterInfo:
    """Add a parameter (e.g. of a motor or a new part) to the global table. Names must be new.

    **Raises:** `ParameterError` when the name is registered with another entry."""
    if info.name in REGISTRY and REGISTRY[info.name] != info:
        raise ParameterError(f"parameter {info.name!r} is already registered differently")
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


def get_value(twin, name: str) -> float:
    """The value (SI) of registry parameter `name` in `twin`, read through its address."""
    return _address(lookup(name)).get(twin)


def set_value(twin, name: str, value):
    """`twin` with registry parameter `name` set to `value` (SI; differentiable), written
    through its address. The part it lives in must exist (:func:`ensure_parts`)."""
    return _address(lookup(name)).set(twin, value)


def ensure_parts(twin, names: Iterable[str]):
    """A twin holding every part the parameters `names` live in (zero-valued parts added where
    missing: bit-identical dynamics)."""
    for n in names:
        info = lookup(n)
        if info.address is not None:
            twin = info.address.ensure(twin)
    return twin


def _address(info: ParameterInfo) -> AbstractAddress:
    if info.address is None:
        raise ParameterError(f"parameter {info.name!r} does not live in a twin (no address): "
                             "it cannot be read from or written into one")
    return info.address


@dataclasses.dataclass(frozen=True)
class RegistryView:
    """The global registry overlaid with `extra` entries (e.g. the parameters of discovery's
    effects), without changing the global table. ``lookup`` and ``names`` as the module's; the
    overlay adds names and never redefines a registered one (``sun_fault`` stays the
    registry's)."""

    extra: Mapping[str, ParameterInfo] = dataclasses.field(default_factory=dict)

    @classmethod
    def of(cls, infos: Iterable[ParameterInfo]) -> RegistryView:
        return cls({i.name: i for i in infos})

    def lookup(self, name: str) -> ParameterInfo:
        if name not in REGISTRY and name in self.extra:
            return self.extra[name]
        return lookup(name)

    def names(self) -> list[str]:
        return sorted(set(REGISTRY) | set(self.extra))
