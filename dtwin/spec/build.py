"""From a spec to a runnable twin: parts chosen from the spec's sections.

`build_twin(spec)` assembles the `Twin` a spec describes:

- lumped parameters (`dtwin.spec.lumped_from_spec`: geometry, ISO 6336 stiffness, inertias,
  planet position errors);
- `Supports`; the spec's `[[faults]]` as `LocalFault` parts; imperfections
  (`SunEccentricity`, `CarrierEccentricity`, `MeshOffsets` for unequal load sharing, its
  clearances solved from the stated shares by `load_share_offsets`) and a `TransmissionError`
  when their values are non-zero;
- the drive of `[motor]` (`dtwin.spec.motor.drive_from_spec`), by default turning at the
  operating speed from the start (``start="steady"``) or stepping from standstill
  (``start="rest"``); the load torque of `[operating]` on the carrier;
- the `PlanetPassTransferPath` of `[sensor]`.

`daq_from_spec(spec)` gives the matching `DAQ` settings.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import jax.numpy as jnp

from ..errors import SpecError
from ..model.faults import AbstractFault, faults_from_table
from ..model.motor.drive import DrivePart, LoadPart
from ..model.motor.loads import ConstantLoad
from ..model.parts.base import AbstractPart
from ..model.parts.imperfections import MeshOffsets, TransmissionError, load_share_offsets
from ..model.parts.local_fault import LocalFault
from ..model.parts.mesh_excitation import excitation_from_table
from ..model.parts.supports import Supports
from ..model.parts.transfer_path import PlanetPassTransferPath
from ..model.registry import lookup
from ..model.twin import Twin
from ..simulation.simulate import DAQ
from . import Spec, load_spec, lumped_from_spec
from .motor import drive_from_spec

_DIRECTIONS = {"vertical": math.pi / 2, "horizontal": 0.0}


def operating_speed(spec) -> float:
    """The spec's input speed `operating.f_sun` (Hz); a clear error when it is missing."""
    f = spec["operating"]["f_sun"]
    if f is None:
        raise SpecError([("operating.f_sun", "is required to simulate: the input (sun) speed in Hz, "
                          "e.g. 30.0 for 1800 rpm")])
    return float(f)


def drive_part(spec, *, start: str = "steady", f_sun: float | None = None) -> DrivePart:
    """The drive of the spec's `[motor]` table; with ``start="steady"`` its speed set point is
    constant at `f_sun` (default `operating.f_sun`), with ``"rest"`` it follows the table's
    `start` (a step from standstill by default)."""
    table = dict(spec["motor"] or {})
    table.setdefault("type", "ideal")
    f = operating_speed(spec) if f_sun is None else float(f_sun)
    if start == "steady":
        table["start"] = "constant"
        if table["type"] == "induction":
            sub = dict(table.get("induction", {}))
            sub.setdefault("supply_frequency", None)
            table["induction"] = {k: v for k, v in sub.items() if v is not None}
        table["speed_rpm"] = 60.0 * f
    elif "speed_rpm" not in table:
        table["speed_rpm"] = 60.0 * f
    return DrivePart(drive_from_spec(table))


def spec_parts(spec, *, faults: tuple[AbstractFault, ...] | None = None) -> list[AbstractPart]:
    """Supports, faults, imperfections and transfer path of a spec (no drive and load)."""
    parts: list[AbstractPart] = [Supports()]
    flts = faults_from_table(spec["faults"]) if faults is None else tuple(faults)
    parts += [LocalFault(f) for f in flts]
    imp = spec["imperfections"]
    for name in ("sun_eccentricity", "carrier_eccentricity"):  # parts built by their address
        if imp[name]:
            parts.append(lookup(name).address.make(float(imp[name])))
    mesh = spec["mesh"]
    if mesh["te_amplitude"]:
        h = jnp.asarray(mesh["te_harmonics"], dtype=jnp.float64)
        parts.append(TransmissionError(jnp.asarray(float(mesh["te_amplitude"])), h, jnp.zeros_like(h)))
    excitation = excitation_from_table(mesh)
    if excitation is not None:
        parts.append(excitation)
    sensor = spec["sensor"]
    direction = sensor["direction"]
    if direction in _DIRECTIONS:
        d_angle = _DIRECTIONS[direction]
    elif direction == "radial":
        d_angle = float(sensor["angle"])
    else:  # tangential
        d_angle = float(sensor["angle"]) + math.pi / 2
    weight = _housing_weight(spec)
    parts.append(
        PlanetPassTransferPath(
            sensor_angle=jnp.asarray(float(sensor["angle"])),
            direction_angle=jnp.asarray(d_angle),
            window_exponent=jnp.asarray(float(sensor["window_exponent"])),
            window_harmonics=(None if sensor["window_harmonics"] is None else
                              jnp.asarray(sensor["window_harmonics"], dtype=jnp.float64)),
            ring_weight=jnp.asarray(weight),
            force_weight=jnp.asarray(weight),
            highpass_hz=jnp.asarray(float(sensor["mount_hz"])),
        )
    )
    return parts


def _housing_weight(spec) -> float:
    """The transfer path's weights ``m_ring / housing_mass`` (1) of the ring's acceleration and of
    the windowed mesh forces: the path reads the forces on the ring over the ring's mass, a
    housing of mass `sensor.housing_mass` (kg) that carries the ring reads them over its own."""
    mass = spec["sensor"]["housing_mass"]
    if mass is None:
        return 1.0
    return float(lumped_from_spec(spec).m_ring) / float(mass)


def load_part(spec, load_torque: float | None = None) -> LoadPart:
    """The carrier load of `[operating]` (N·m)."""
    tl = spec["operating"]["load_torque"] if load_torque is None else load_torque
    return LoadPart(ConstantLoad(jnp.asarray(float(tl or 0.0))))


#: The twin a fitting command (identify, severity, fleet) builds from a spec that was not
#: calibrated, when none is asked for: the torsional reduction, which the mesh-band lines of a
#: steady record need and which simulates fastest.
FIT_KIND = "torsional"


#: The twin a tooth fault's severity is fitted with when none is asked
#: (:func:`dtwin.identify.severity.estimate_severity`, ``dtwin severity``), whatever the spec's
#: own kind: the translational twin. A local tooth fault loads one mesh at a time; where the
#: sun floats on its bearing, as in most planetary gearboxes, it moves under that loss, and the
#: torsional twin, whose sun and planets cannot move sideways, makes a sun or planet fault
#: 4–10× louder and so fits it 4–10× too small (docs/identification.md, "The twin of a
#: severity"; the measurements in benchmarks/history.md).
SEVERITY_KIND = "translational"


#: Registry names of the local tooth faults' severities.
TOOTH_FAULTS = ("sun_fault", "planet_fault", "ring_fault")


def warn_torsional_tooth_fault(kind: str, free) -> None:
    """A `UserWarning` when a fit of the `free` registry names with the `kind` twin fits a
    tooth fault's severity with the torsional twin (:data:`SEVERITY_KIND`): ``dtwin identify``
    and ``dtwin fleet`` follow the spec's kind, ``dtwin severity`` does not."""
    faults = [n for n in free if n in TOOTH_FAULTS]
    if kind == "torsional" and faults:
        warnings.warn(f"{', '.join(faults)} fitted with the torsional twin: where the sun "
                      "floats on its bearing (most planetary gearboxes) it reads sun and planet "
                      "tooth faults 4–10× small; --model translational (dtwin severity's "
                      "default) for the twin whose bodies move", UserWarning, stacklevel=2)


def is_calibrated(spec) -> bool:
    """Whether `spec` (a `Spec`, path or mapping) was written by ``dtwin calibrate`` (it has
    ``[calibration] records``)."""
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    return spec["calibration"]["records"] is not None


def twin_kind(spec, kind: str | None = None, default: str = FIT_KIND) -> str:
    """The twin kind (``translational`` / ``torsional``) a fitting command builds for `spec`.

    - `kind` given: that kind. When the spec was calibrated (it has ``[calibration]``) for the
      other kind, a `UserWarning` says so: its calibrated excitation, window, sensor response
      and load shares were fitted with that twin and mean something else in this one.
    - `kind` None: a calibrated spec's ``model.kind`` (the twin it was calibrated with, which
      ``dtwin calibrate`` writes there); otherwise `default`.

    **Raises:** `SpecError` for an unknown `kind`.
    """
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    calibrated = is_calibrated(spec)
    own = spec["model"]["kind"]
    if kind is None:
        return own if calibrated else default
    if kind not in ("translational", "torsional"):
        raise SpecError([("model.kind", f"the twin kind is 'translational' or 'torsional', "
                                        f"got {kind!r}")])
    if calibrated and kind != own:
        warnings.warn(f"this spec was calibrated with the {own} twin: its calibrated excitation, "
                      f"window, sensor response and load shares were fitted for that twin, not "
                      f"the {kind} one asked for; leave the kind out (or ask for {own}) to use "
                      "the twin it was calibrated with", UserWarning, stacklevel=2)
    return kind


def build_twin(
    spec,
    *,
    kind: str | None = None,
    faults: tuple[AbstractFault, ...] | None = None,
    start: str = "steady",
    f_sun: float | None = None,
    extra_parts: tuple[AbstractPart, ...] = (),
    n_harmonics: int | None = None,
) -> Twin:
    """The `Twin` a spec describes (module docstring).

    **Arguments:**

    - `spec`: a `dtwin.spec.Spec` (or a path/mapping for `load_spec`).
    - `kind`: ``translational`` / ``torsional`` (default `model.kind`).
    - `faults`: replace the spec's faults (e.g. from the CLI's ``--fault``).
    - `start`: ``steady`` (drive at constant speed) or ``rest`` (the drive's start profile).
    - `f_sun`: input speed (Hz) overriding `operating.f_sun`.
    - `extra_parts`: further parts (effects) to add.
    - `n_harmonics`: stiffness Fourier harmonics (default `mesh.n_harmonics`).
    """
    if not isinstance(spec, Spec):
        spec = load_spec(spec)
    kind = kind or spec["model"]["kind"]
    lp = lumped_from_spec(spec, model=kind)
    parts = spec_parts(spec, faults=faults)
    parts.insert(1, drive_part(spec, start=start, f_sun=f_sun))
    parts.insert(2, load_part(spec))
    nh = int(n_harmonics or spec["mesh"]["n_harmonics"])
    shares = spec["imperfections"]["load_sharing"]
    if shares is not None:
        n = spec["gears"]["n_planets"]
        if len(shares) != n or not all(float(v) > 0 for v in shares):
            raise SpecError([("imperfections.load_sharing",
                              f"needs {n} positive values (one relative share per planet), "
                              f"got {list(shares)}")])
        # clearances from the static balance of the twin as built so far (drive, load,
        # supports, faults, excitations): the shares hold at the spec's load
        speed = f_sun if f_sun is not None else spec["operating"]["f_sun"]
        if speed is None:
            raise SpecError([("imperfections.load_sharing", "the shares hold at a load and "
                              "speed: set operating.f_sun (Hz)")])
        e = load_share_offsets(Twin(lp, tuple(parts), kind=kind, n_harmonics=nh), shares,
                               float(speed))
        parts.append(MeshOffsets(e, e))
    parts += list(extra_parts)
    return Twin(lp, tuple(parts), kind=kind, n_harmonics=nh)


def daq_from_spec(spec, **overrides: Any) -> DAQ:
    """`DAQ` settings of the spec's `[sensor]` table, with keyword overrides."""
    s = spec["sensor"]
    kw: dict[str, Any] = dict(
        sample_rate=float(s["sample_rate"]),
        oversample=int(s["oversample"]),
        quantity=s["quantity"],
        gain=float(s["gain"]),
        snr_db=s["snr_db"],
        tacho_ppr=s["tacho_ppr"],
        tacho_shaft=s["tacho_shaft"],
        frf_hz=None if s["frf_hz"] is None else tuple(s["frf_hz"]),
        frf_db=None if s["frf_db"] is None else tuple(s["frf_db"]),
        passband=float(s["passband"]),
    )
    kw.update(overrides)
    return DAQ(**kw)
