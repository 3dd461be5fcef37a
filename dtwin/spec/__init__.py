"""Gearbox spec files (TOML): schema, validation, presets and the lumped parameters they imply.

A spec describes one planetary gearbox and how it runs, in SI units throughout (m, kg, s, rad,
Hz, N/m, N·m/rad). :func:`load_spec` reads a TOML file (or takes a mapping), checks every
value, fills the defaults and returns a frozen :class:`Spec`; all problems are collected and
raised together as one :class:`~dtwin.errors.SpecError` whose ``problems`` list names each field
(``"gears.module"``) with a message that says what to change, including likely unit slips
(``gears.module = 2: did you mean 2 mm = 0.002 m?``). Unknown sections and keys are errors, with
a close match suggested. Registered parameters (:mod:`dtwin.model.registry`) use the registry's
plausible range; the others use the ranges of :data:`SCHEMA`. The schema is documented field by
field in ``docs/spec.md``.

:func:`lumped_from_spec` turns a spec into :class:`~dtwin.model.lumped.LumpedParameters`: geometry from
:class:`~dtwin.model.gears.GearSet`, masses and inertias from the geometry and mesh stiffness from
ISO 6336-1 (:func:`dtwin.model.stiffness.mesh_stiffness_mean`) unless the spec gives them (sections
``[mesh]`` and ``[lumped]`` win over geometry).

Presets ship as TOML files inside the package, ``dtwin/spec/presets/``: ``paper-sim``, ``paper-bench``, ``lin-parker``
(:func:`preset`).
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import math
import os
import tomllib
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..errors import GeometryError, SpecError, UnreadableFileError
from ..model.gears import (
    GearSet,
    base_radii,
    contact_ratios,
    masses_and_inertias,
    operating_pressure_angles,
    reference_radii,
    relative_mesh_phase,
)
from ..model.lumped import make_lumped
from ..model.registry import REGISTRY
from ..model.stiffness import mesh_stiffness_mean
from .motor import drive_from_spec

SPECS_DIR = Path(__file__).resolve().parent / "presets"
"""Folder of the bundled preset specs (``dtwin/spec/presets/*.toml``, installed with the package)."""

PRESETS = ("paper-sim", "paper-bench", "paper-like", "lin-parker")
"""Names of the bundled presets."""

_REQUIRED = object()


@dataclasses.dataclass(frozen=True)
class FieldSpec:
    """One field of the spec schema.

    - `kind`: ``int``, ``float``, ``str`` (one of `choices`), ``floats`` (list of floats),
      ``bool``.
    - `unit`: SI unit (``1`` for dimensionless).
    - `default`: value when the key is absent (``None``: optional, no value; :data:`_REQUIRED`:
      must be given).
    - `lo`, `hi`: plausible range (inclusive); ``None`` for open. Registered names take the
      registry's range.
    - `choices`: allowed strings for ``str`` fields (empty: any text).
    - `doc`: one line for ``docs/spec.md``.
    - `registry`: the registry name when the field is a registered parameter.
    """

    kind: str
    unit: str = "1"
    default: Any = None
    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] = ()
    doc: str = ""
    registry: str | None = None

    @property
    def required(self) -> bool:
        return self.default is _REQUIRED

    def range(self) -> tuple[float | None, float | None]:
        if self.registry is not None:
            return REGISTRY[self.registry].plausible
        return self.lo, self.hi


def _reg(name: str, default: Any = None, doc: str | None = None) -> FieldSpec:
    info = REGISTRY[name]
    return FieldSpec("float", info.unit, default, doc=doc or info.description, registry=name)


_DEG = math.pi / 180.0

SCHEMA: dict[str, dict[str, FieldSpec]] = {
    "gears": {
        "z_sun": FieldSpec("int", "1", _REQUIRED, 3, 1000, doc="sun tooth count"),
        "z_planet": FieldSpec("int", "1", _REQUIRED, 3, 1000, doc="planet tooth count"),
        "z_ring": FieldSpec("int", "1", _REQUIRED, 6, 3000, doc="ring tooth count"),
        "n_planets": FieldSpec("int", "1", _REQUIRED, 1, 20, doc="number of planets N"),
        "module": FieldSpec("float", "m", _REQUIRED, 1e-4, 0.1, doc="module m"),
        "pressure_angle": FieldSpec("float", "rad", 20 * _DEG, 10 * _DEG, 35 * _DEG,
                                    doc="reference (basic rack) pressure angle α"),
        "face_width": FieldSpec("float", "m", _REQUIRED, 1e-3, 2.0, doc="face width b"),
        "x_sun": FieldSpec("float", "1", None, -1.0, 1.5,
                           doc="sun profile shift coefficient (modules)"),
        "x_planet": FieldSpec("float", "1", None, -1.0, 1.5,
                              doc="planet profile shift coefficient (modules)"),
        "x_ring": FieldSpec("float", "1", None, -1.5, 1.5,
                            doc="ring profile shift coefficient (modules; > 0 moves the ring's "
                                "profile away from its centre)"),
        "centre_distance": FieldSpec("float", "m", None, 1e-3, 10.0,
                                     doc="operating centre distance a (carrier radius)"),
        "planet_angles": FieldSpec("floats", "rad", None, -2 * math.pi, 4 * math.pi,
                                   doc="carrier-frame planet angles ψ_i (default 2πi/N)"),
    },
    "material": {
        "youngs_modulus": FieldSpec("float", "Pa", 2.06e11, 1e9, 1e12, doc="Young's modulus E"),
        "poisson": FieldSpec("float", "1", 0.3, 0.0, 0.5, doc="Poisson's ratio ν"),
        "density": FieldSpec("float", "kg/m^3", 7850.0, 1000.0, 20000.0, doc="density ρ"),
    },
    "mesh": {
        "k_sun_planet": _reg("k_sun_planet", doc="mean sun-planet mesh stiffness (default: ISO "
                                                 "6336-1 from the geometry and load)"),
        "k_ring_planet": _reg("k_ring_planet", doc="mean ring-planet mesh stiffness (default: "
                                                   "ISO 6336-1)"),
        "te_amplitude": _reg("te_amplitude", 0.0),
        "te_harmonics": FieldSpec("floats", "1", [1.0], 0.0, 10.0,
                                  doc="relative amplitudes of the TE harmonics 1, 2, …"),
        "n_harmonics": FieldSpec("int", "1", 12, 1, 200,
                                 doc="Fourier harmonics of the stiffness waveform"),
        "application_factor": FieldSpec("float", "1", 1.0, 1.0, 3.0,
                                        doc="ISO 6336 application factor K_A"),
        **{f"excitation_{m}_{cs}": FieldSpec(
            "floats", "m", None, -1e-3, 1e-3,
            doc=f"calibrated transmission-error {cs}ine coefficients of the {m}-planet meshes, "
                "mesh harmonics 1, 2, … (dtwin/model/parts/mesh_excitation.py)")
           for m in ("sun", "ring") for cs in ("cos", "sin")},
    },
    "supports": {
        "k_bearing_sun": _reg("k_bearing_sun", 1e8),
        "k_bearing_ring": _reg("k_bearing_ring", 1e8),
        "k_bearing_carrier": _reg("k_bearing_carrier", 1e8),
        "k_bearing_planet": _reg("k_bearing_planet", 1e8),
        "k_torsion_sun": FieldSpec("float", "N*m/rad", 0.0, 0.0, 1e10,
                                   doc="sun torsional spring to ground (normally 0)"),
        "k_torsion_ring": _reg("k_torsion_ring", 6e6, doc="ring torsional support stiffness; the default is Lin & Parker's 1e9 N/m on u = r θ for the paper's ring (r_b ≈ 76 mm)"),
        "k_torsion_carrier": FieldSpec("float", "N*m/rad", 0.0, 0.0, 1e10,
                                       doc="carrier torsional spring to ground (normally 0)"),
    },
    "damping": {
        "zeta_mesh": _reg("zeta_mesh", None, doc="damping ratio of both meshes (sets the two "
                                                 "below; give either this or them)"),
        "zeta_sun_planet": _reg("zeta_sun_planet", 0.07),
        "zeta_ring_planet": _reg("zeta_ring_planet", 0.07),
        "zeta_support": _reg("zeta_support", 0.03),
    },
    "lumped": {
        **{f"m_{b}": _reg(f"m_{b}", doc=f"{b} mass (default: from geometry)")
           for b in ("sun", "ring", "carrier", "planet")},
        **{f"J_{b}": _reg(f"J_{b}", doc=f"{b} polar moment of inertia (default: from geometry)")
           for b in ("sun", "ring", "carrier", "planet")},
        **{f"Ir2_{b}": FieldSpec("float", "kg", None, 1e-4, 1e5,
                                 doc=f"{b} I/r² as Lin & Parker give it (r = base radius; "
                                     "carrier: centre distance); J = Ir2·r²")
           for b in ("sun", "ring", "carrier", "planet")},
        **{f"k_u_torsion_{b}": FieldSpec("float", "N/m", None, 0.0, 1e12,
                                         doc=f"{b} torsional support on u = r θ (Lin & Parker; "
                                             "r as for Ir2); k_torsion = k_u·r²")
           for b in ("sun", "ring", "carrier")},
    },
    "operating": {
        "f_sun": _reg("f_sun", None, doc="input (sun) rotation frequency (the paper's f_sr)"),
        "load_torque": _reg("load_torque", 0.0),
    },
    "sensor": {
        "angle": FieldSpec("float", "rad", math.pi / 2, -2 * math.pi, 2 * math.pi,
                           doc="housing angle of the sensor (CCW from +x; π/2 = on top)"),
        "direction": FieldSpec("str", "", "vertical", choices=("vertical", "horizontal",
                                                               "radial", "tangential"),
                               doc="measuring direction"),
        "quantity": FieldSpec("str", "", "acceleration",
                              choices=("acceleration", "velocity", "displacement",
                                       "ring_velocity"),
                              doc="measured quantity (ring_velocity: the ring's velocity along "
                                  "the sensor axis, what the paper's simulation plotted)"),
        "window_exponent": FieldSpec("float", "1", 4.0, 0.0, 64.0,
                                     doc="transfer-path window ((1 + cos φ)/2)^p of a planet's "
                                         "angle φ to the sensor (dtwin/model/parts/transfer_path.py)"),
        "housing_mass": FieldSpec("float", "kg", None, 1e-2, 1e5,
                                  doc="mass of the housing the sensor sits on, gear set included: "
                                      "a dynamic mesh force F reads F / housing_mass at the sensor "
                                      "(none: the ring's mass, a ring without a housing)"),
        "mount_hz": FieldSpec("float", "Hz", 50.0, 0.1, 1e4,
                              doc="rigid-body resonance of the housing on its mounts: below it "
                                  "the sensor sees a slow force through the mounts' stiffness "
                                  "(acceleration falling as f²), above it through the mass"),
        "passband": FieldSpec("float", "1", 0.45, 0.3, 0.49,
                              doc="end of the DAQ's anti-aliasing pass band, a fraction of "
                                  "sample_rate: 0.45 for a delta-sigma DAQ (the default), "
                                  "0.39 (1/2.56) for a classic analyser; the twin's filter "
                                  "passes flat to it and the gaps are scored up to it"),
        "oversample": FieldSpec("int", "1", 4, 2, 64,
                                doc="internal simulation rate over the DAQ rate (anti-aliasing)"),
        "tacho_ppr": FieldSpec("int", "1", None, 1, 10000,
                               doc="tachometer pulses per revolution (none: no tachometer)"),
        "tacho_shaft": FieldSpec("str", "", "sun", choices=("sun", "carrier"),
                                 doc="shaft the tachometer sees"),
        "sample_rate": FieldSpec("float", "Hz", 5000.0, 100.0, 1e6, doc="DAQ sampling rate"),
        "gain": _reg("sensor_gain", 1.0),
        "snr_db": FieldSpec("float", "dB", None, -20.0, 200.0,
                            doc="signal-to-noise ratio over the record (none: no noise)"),
        "window": FieldSpec("str", "", "hann",
                            choices=("hann", "hamming", "blackman", "flattop", "rect"),
                            doc="spectral window"),
        "window_harmonics": FieldSpec("floats", "1", None, -100.0, 100.0,
                                      doc="calibrated window shape: cosine coefficients c_0, c_1, "
                                          "… of the planet-angle window (replaces "
                                          "window_exponent)"),
        "frf_hz": FieldSpec("floats", "Hz", None, 1e-2, 1e6,
                            doc="knots of the smooth sensor frequency response, increasing "
                                "(dtwin/simulation/sensor_response.py)"),
        "frf_db": FieldSpec("floats", "dB", None, -300.0, 300.0,
                            doc="gains of the sensor frequency response at frf_hz (dB re 1)"),
    },
    "calibration": {
        "records": FieldSpec("str", "", None, doc="healthy records the calibration was fitted "
                                                  "on (written by dtwin calibrate)"),
        "heldout_gap_db": FieldSpec("float", "dB", None, 0.0, 500.0,
                                    doc="held-out gap of the calibrated twin on its records"),
        "created_by": FieldSpec("str", "", None, doc="dtwin version that calibrated the spec"),
        "shortfall_orders": FieldSpec("floats", "1", None, 0.0, 1e4,
                                      doc="lines the calibrated twin left unexplained on its "
                                          "records, as orders of the input speed (written by "
                                          "dtwin calibrate; discovery refuses a candidate whose "
                                          "evidence lies there)"),
        "shortfall_db": FieldSpec("floats", "dB", None, 0.0, 500.0,
                                  doc="each shortfall line's excess over the other spectrum"),
        "kept_spec": FieldSpec("str", "", None,
                               doc="present when the calibrated values were not adopted "
                                   "(dtwin.identify.calibrate.adoption): the spec's own values "
                                   "were kept, with only the sensor's response level fitted "
                                   "(says why)"),
    },
    "imperfections": {
        "planet_position_errors": FieldSpec(
            "floats", "rad", None, -0.1, 0.1,
            doc="planet spacing errors added to ψ_i (N values): mesh phases and sensor windows "
                "move, the load stays shared equally"),
        "sun_eccentricity": _reg("sun_eccentricity", 0.0),
        "carrier_eccentricity": _reg("carrier_eccentricity", 0.0),
        "load_sharing": FieldSpec("floats", "1", None, 0.0, 3.0,
                                  doc="relative load share of each planet (N positive values, read "
                                      "relative to their mean): the meshes get the clearances "
                                      "that give these shares at the spec's load"),
    },
    "motor": {
        "type": FieldSpec("str", "", "ideal", choices=("ideal", "pmsm", "induction"),
                          doc="drive model; further keys (speed_rpm, start, k_shaft, sub-tables "
                              "[motor.pmsm], [motor.induction]) are validated by "
                              "dtwin.spec.motor: see docs/motor.md"),
    },
    "model": {
        "kind": FieldSpec("str", "", "translational", choices=("translational", "torsional"),
                          doc="lumped model: translational-rotational or torsional"),
    },
}

FAULT_SCHEMA: dict[str, FieldSpec] = {
    "location": FieldSpec("str", "", _REQUIRED, choices=("sun", "planet", "ring"),
                          doc="faulty gear"),
    "type": FieldSpec("str", "", _REQUIRED, choices=("missing_tooth", "pitting", "crack"),
                      doc="fault type"),
    "severity": FieldSpec("float", "1", _REQUIRED, 0.0, 1.0,
                          doc="physical severity in [0, 1] (see dtwin.model.faults)"),
    "tooth": FieldSpec("int", "1", 0, 0, 10000, doc="index of the faulty tooth on its gear"),
    "planet": FieldSpec("int", "1", 0, 0, 100, doc="which planet (planet faults)"),
    "flank": FieldSpec("str", "", None, choices=("sun", "ring", "both"),
                       doc="planet faults: flank meeting the sun, the ring or both (default: "
                           "the fault type's)"),
}

BEARING_SCHEMA: dict[str, FieldSpec] = {
    "n_rolling_elements": FieldSpec("int", "1", _REQUIRED, 3, 200, doc="number of rolling "
                                                                        "elements"),
    "ball_diameter": FieldSpec("float", "m", _REQUIRED, 1e-4, 0.3, doc="rolling element "
                                                                       "diameter"),
    "pitch_diameter": FieldSpec("float", "m", _REQUIRED, 1e-3, 3.0, doc="pitch diameter"),
    "contact_angle": FieldSpec("float", "rad", 0.0, 0.0, 80 * _DEG, doc="contact angle"),
}
BEARING_LOCATIONS = ("sun", "planet", "carrier")

SPEED_PROFILE_SCHEMA: dict[str, FieldSpec] = {
    "t": FieldSpec("floats", "s", _REQUIRED, 0.0, 1e6, doc="times, increasing"),
    "f_sun": FieldSpec("floats", "Hz", _REQUIRED, 0.0, 500.0, doc="sun frequency at those times"),
}

_TOP_LEVEL = ("name", "description", "source")  # source: written by spec_to_dict (round trip)
_SECTIONS = (*SCHEMA, "faults", "bearings")


# --- value checks --------------------------------------------------------------------------------


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def _unit_hint(v: float, unit: str, lo: float | None, hi: float | None, path: str = "") -> str:
    """A 'did you mean' for a value that fits the range once converted from a common unit
    (rpm only for rotation frequencies, ``*.f_sun``)."""
    if lo is None or hi is None:
        return ""
    if unit == "Hz" and not path.split("[")[0].endswith("f_sun"):
        return ""
    candidates: list[tuple[float, str]] = {
        "m": [(1e-3, "mm"), (1e-6, "µm"), (1e-2, "cm")],
        "rad": [(_DEG, "°")],
        "Hz": [(1 / 60, "rpm")],
        "N/m": [(1e3, "N/mm"), (1e6, "N/µm")],
        "Pa": [(1e9, "GPa"), (1e6, "MPa")],
        "kg/m^3": [(1e3, "g/cm³")],
        "kg": [(1e-3, "g")],
        "kg*m^2": [(1e-6, "kg·mm²")],
    }.get(unit, [])
    for factor, name in candidates:
        w = v * factor
        if lo <= w <= hi and w != 0:
            sep = "" if name == "°" else " "
            return f": did you mean {_fmt(v)}{sep}{name} = {_fmt(w)} {unit}?"
    return ""


def _check_number(path: str, v: Any, f: FieldSpec, problems: list) -> Any:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        problems.append((path, f"must be a number ({f.unit}), got {v!r}"))
        return None
    if f.kind == "int" and not (isinstance(v, int) or float(v).is_integer()):
        problems.append((path, f"must be an integer, got {v!r}"))
        return None
    if not math.isfinite(float(v)):
        problems.append((path, f"must be finite, got {v!r}"))
        return None
    lo, hi = f.range()
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        hint = _unit_hint(float(v), f.unit, lo, hi, path)
        unit = "" if f.unit == "1" else f" {f.unit}"
        rng = (f"plausible range {_fmt(lo) if lo is not None else '-inf'} .. "
               f"{_fmt(hi) if hi is not None else 'inf'}{unit}")
        what = f"{path} = {_fmt(float(v))}"
        problems.append((path, f"{what}{hint} ({rng})" if hint else
                         f"{what} is outside the {rng}"))
        return None
    return int(v) if f.kind == "int" else float(v)


def _check_value(path: str, v: Any, f: FieldSpec, problems: list) -> Any:
    if f.kind in ("int", "float"):
        return _check_number(path, v, f, problems)
    if f.kind == "str":
        if not f.choices and isinstance(v, str):  # free text (e.g. [calibration] provenance)
            return v
        if not isinstance(v, str) or v not in f.choices:
            close = [c for c in f.choices if isinstance(v, str) and v and c.startswith(v)]
            close = close or difflib.get_close_matches(str(v), f.choices, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            problems.append((path, f"must be one of {', '.join(f.choices)}, got {v!r}{hint}"))
            return None
        return v
    if f.kind == "bool":
        if not isinstance(v, bool):
            problems.append((path, f"must be true or false, got {v!r}"))
            return None
        return v
    if f.kind == "floats":
        if not isinstance(v, (list, tuple)):
            problems.append((path, f"must be a list of numbers ({f.unit}), got {v!r}"))
            return None
        out = []
        n_before = len(problems)
        item = dataclasses.replace(f, kind="float")
        for i, x in enumerate(v):
            out.append(_check_number(f"{path}[{i}]", x, item, problems))
        return out if len(problems) == n_before else None
    raise AssertionError(f.kind)


def _unknown(path: str, key: str, allowed: Any) -> tuple[str, str]:
    close = difflib.get_close_matches(key, list(allowed), n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    where = f"in [{path}]" if path else "at the top level"
    return (f"{path}.{key}" if path else key,
            f"unknown key {key!r} {where}{hint} (allowed: {', '.join(allowed)})")


def _check_table(path: str, table: Any, schema: Mapping[str, FieldSpec],
                 problems: list) -> dict[str, Any]:
    if not isinstance(table, Mapping):
        problems.append((path, f"must be a table, got {type(table).__name__}"))
        return {}
    out: dict[str, Any] = {}
    table = {k: v for k, v in table.items() if v is not None}  # None = absent (dict input)
    for key, val in table.items():
        if key not in schema:
            problems.append(_unknown(path, key, schema))
            continue
        out[key] = _check_value(f"{path}.{key}", val, schema[key], problems)
    for key, f in schema.items():
        if key not in table:
            if f.required:
                problems.append((f"{path}.{key}", f"is required ({f.doc}, {f.unit})"))
                out[key] = None
            else:
                out[key] = copy.deepcopy(f.default)
    return out


# --- the Spec ------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Spec:
    """A validated gearbox spec: every section present, defaults filled, SI values.

    - `data`: nested dict ``section -> key -> value`` (plus ``faults``: list of dicts and
      ``bearings``: dict location -> dict); treat as read-only (use :func:`spec_to_dict` for a
      copy).
    - `source`: the file it was read from, if any.

    ``spec["gears"]["module"]`` reads a value; :meth:`gear_set` builds the
    :class:`~dtwin.model.gears.GearSet`.
    """

    data: Mapping[str, Any]
    source: str | None = None

    def __getitem__(self, section: str) -> Any:
        return self.data[section]

    @property
    def name(self) -> str:
        return self.data.get("name") or (Path(self.source).stem if self.source else "spec")

    def gear_set(self):
        """The :class:`~dtwin.model.gears.GearSet` of ``[gears]`` (warnings were shown at load)."""
        return _gear_set(self.data["gears"], quiet=True)


def _gear_set(g: Mapping[str, Any], *, quiet: bool):
    kw = {k: v for k, v in g.items() if v is not None}
    with warnings.catch_warnings():
        if quiet:
            warnings.simplefilter("ignore")
        return GearSet(**kw)


def _validate(raw: Mapping[str, Any]) -> dict[str, Any]:
    problems: list[tuple[str, str]] = []
    data: dict[str, Any] = {}
    for key in raw:
        if key not in _SECTIONS and key not in _TOP_LEVEL:
            problems.append(_unknown("", key, (*_SECTIONS, *_TOP_LEVEL)))
    for key in _TOP_LEVEL:
        v = raw.get(key)
        if v is not None and not isinstance(v, str):
            problems.append((key, f"must be a string, got {v!r}"))
        data[key] = v if isinstance(v, str) else None

    for section, schema in SCHEMA.items():
        table = raw.get(section, {})
        if section == "motor":
            data[section] = _check_motor(table, problems)
        elif section == "operating":
            data[section] = _check_operating(table, problems)
        else:
            data[section] = _check_table(section, table, schema, problems)

    # [damping]: zeta_mesh is a tie for both meshes
    d, draw = data["damping"], raw.get("damping", {})
    if isinstance(draw, Mapping) and d.get("zeta_mesh") is not None:
        for k in ("zeta_sun_planet", "zeta_ring_planet"):
            if draw.get(k) is not None and draw[k] != d["zeta_mesh"]:
                problems.append((f"damping.{k}", "given together with damping.zeta_mesh, which "
                                 "sets both mesh damping ratios; give one or the other"))
            d[k] = d["zeta_mesh"]

    # [lumped]: J and Ir2 of the same body exclude each other
    lum = data["lumped"]
    for b in ("sun", "ring", "carrier", "planet"):
        if lum.get(f"J_{b}") is not None and lum.get(f"Ir2_{b}") is not None:
            problems.append((f"lumped.Ir2_{b}", f"give lumped.J_{b} (kg·m²) or lumped.Ir2_{b} "
                             "(kg), not both"))

    # [[faults]]
    faults_raw = raw.get("faults", [])
    faults = []
    if isinstance(faults_raw, Mapping):
        faults_raw = [faults_raw]
    if not isinstance(faults_raw, list):
        problems.append(("faults", "must be an array of tables ([[faults]])"))
        faults_raw = []
    for i, fr in enumerate(faults_raw):
        faults.append(_check_table(f"faults[{i}]", fr, FAULT_SCHEMA, problems))
    data["faults"] = faults

    # [bearings.<location>]
    bearings: dict[str, Any] = {}
    braw = raw.get("bearings", {})
    if not isinstance(braw, Mapping):
        problems.append(("bearings", "must be a table of [bearings.sun|planet|carrier] tables"))
        braw = {}
    for loc, table in braw.items():
        if loc not in BEARING_LOCATIONS:
            problems.append(_unknown("bearings", loc, BEARING_LOCATIONS))
            continue
        b = _check_table(f"bearings.{loc}", table, BEARING_SCHEMA, problems)
        if b.get("ball_diameter") is not None and b.get("pitch_diameter") is not None and \
                b["ball_diameter"] >= b["pitch_diameter"]:
            problems.append((f"bearings.{loc}.ball_diameter", "must be smaller than "
                             "pitch_diameter"))
        bearings[loc] = b
    data["bearings"] = bearings

    _check_cross(data, problems)
    if problems:
        raise SpecError(problems)
    return data


def _check_motor(table: Any, problems: list) -> dict[str, Any]:
    """`[motor]`: validated by the motor module (`dtwin.spec.motor.drive_from_spec`), which
    knows every drive's parameters, defaults and plausible ranges; problems carry their paths."""
    if not isinstance(table, Mapping):
        problems.append(("motor", "must be a table"))
        return {"type": "ideal"}
    out: dict[str, Any] = {"type": _check_value("motor.type", table.get("type", "ideal"),
                                                SCHEMA["motor"]["type"], problems)}
    for k, v in table.items():
        if k == "type":
            continue
        out[k] = dict(v) if isinstance(v, Mapping) else v
    try:
        drive_from_spec(dict(out))
    except SpecError as e:
        problems.extend(e.problems)
    return out


def _check_operating(table: Any, problems: list) -> dict[str, Any]:
    if not isinstance(table, Mapping):
        problems.append(("operating", "must be a table"))
        return {}
    plain = {k: v for k, v in table.items() if k != "speed_profile"}
    out = _check_table("operating", plain, SCHEMA["operating"], problems)
    out["speed_profile"] = None
    if table.get("speed_profile") is not None:
        sp = _check_table("operating.speed_profile", table["speed_profile"],
                          SPEED_PROFILE_SCHEMA, problems)
        t, f = sp.get("t"), sp.get("f_sun")
        if t is not None and f is not None:
            if len(t) != len(f) or len(t) < 2:
                problems.append(("operating.speed_profile", "t and f_sun need the same length "
                                 f"(at least 2), got {len(t)} and {len(f)}"))
            elif any(b <= a for a, b in zip(t, t[1:], strict=False)):
                problems.append(("operating.speed_profile.t", "times must increase strictly"))
        out["speed_profile"] = sp
    return out


def _tooth_count_rule(g: Mapping[str, Any], found: list) -> list:
    """The gear set's problems, with a centre distance the spec never gave restated as the
    tooth-count rule it breaks: without ``centre_distance`` or shifts, dtwin takes the mean of
    the two meshes' standard centre distances, which exists only when ``z_ring`` is within a few
    teeth of ``z_sun + 2 z_planet`` (profile shift closes a small difference, not a large one)."""
    given = any(g.get(k) is not None for k in ("centre_distance", "x_sun", "x_planet", "x_ring"))
    if given:
        return list(found)
    zs, zp, zr = int(g["z_sun"]), int(g["z_planet"]), int(g["z_ring"])
    out = []
    for path, msg in found:
        if path == "gears.centre_distance":
            path, msg = "gears.z_ring", (
                f"z_ring = {zr} but z_sun + 2 z_planet = {zs + 2 * zp} (z_sun = {zs}, z_planet = "
                f"{zp}): the rule z_ring = z_sun + 2 z_planet, which profile shift bends by a "
                "tooth or two only, is broken by too much for the sun-planet and ring-planet "
                "meshes to share one carrier radius; change z_ring, z_sun or z_planet (or give "
                "gears.centre_distance or the profile shifts of your gearbox)")
        if (path, msg) not in out:
            out.append((path, msg))
    return out


def _check_cross(data: dict[str, Any], problems: list) -> None:
    """Checks that need several fields: the gear geometry, fault indices, per-planet lists."""
    s = data["sensor"]
    hz, db = s.get("frf_hz"), s.get("frf_db")
    if hz is not None and any(b <= a for a, b in zip(hz, hz[1:], strict=False)):
        problems.append(("sensor.frf_hz", "knots must be increasing (Hz)"))
    if (hz is None) != (db is None) or (hz is not None and len(hz) != len(db)):
        problems.append(("sensor.frf_db", "give sensor.frf_hz and sensor.frf_db together, one "
                         "gain per knot"))
    g = data["gears"]
    if any(g.get(k) is None for k in ("z_sun", "z_planet", "z_ring", "n_planets", "module",
                                      "face_width")):
        return  # already reported
    if any(p.startswith("gears.") for p, _ in problems):
        return
    try:
        gs = _gear_set(g, quiet=False)
    except GeometryError as e:
        problems.extend(_tooth_count_rule(g, e.problems))
        return
    n = gs.n_planets
    z = {"sun": gs.z_sun, "planet": gs.z_planet, "ring": gs.z_ring}
    for i, f in enumerate(data["faults"]):
        loc = f.get("location")
        if loc in z and f.get("tooth") is not None and f["tooth"] >= z[loc]:
            problems.append((f"faults[{i}].tooth", f"the {loc} has teeth 0..{z[loc] - 1}, got "
                             f"{f['tooth']}"))
        if loc == "planet" and f.get("planet") is not None and f["planet"] >= n:
            problems.append((f"faults[{i}].planet", f"planets are numbered 0..{n - 1}, got "
                             f"{f['planet']}"))
        if loc != "planet" and f.get("flank") is not None:
            problems.append((f"faults[{i}].flank", "only planet faults have a flank (sun|ring|"
                             "both)"))
    imp = data["imperfections"]
    for k in ("planet_position_errors", "load_sharing"):
        if imp.get(k) is not None and len(imp[k]) != n:
            problems.append((f"imperfections.{k}", f"needs one value per planet ({n}), got "
                             f"{len(imp[k])}"))


def load_spec(source: str | os.PathLike | Mapping[str, Any]) -> Spec:
    """Read and validate a spec.

    **Arguments:** `source`: path of a TOML file, or a mapping with the same structure.

    **Returns:** a :class:`Spec` with every section present and the defaults filled.

    **Raises:** :class:`~dtwin.errors.SpecError` listing every problem as (field path, message);
    :class:`~dtwin.errors.UnreadableFileError` if the file cannot be read.
    """
    if isinstance(source, Mapping):
        return Spec(_validate(source), None)
    path = Path(source)
    try:
        with open(path, "rb") as f:
            raw = tomllib.load(f)
    except FileNotFoundError:
        raise UnreadableFileError(f"spec file {path} does not exist") from None
    except tomllib.TOMLDecodeError as e:
        raise SpecError([("", f"{path} is not valid TOML: {e}")]) from None
    except UnicodeDecodeError as e:
        raise SpecError([("", f"{path} is not UTF-8 text (TOML must be UTF-8): {e}")]) from None
    except OSError as e:
        raise UnreadableFileError(f"cannot read spec file {path}: {e}") from None
    return Spec(_validate(raw), str(path))


def preset(name: str) -> Spec:
    """A bundled preset spec: ``paper-sim``, ``paper-bench``, ``paper-like`` or ``lin-parker``."""
    if name not in PRESETS:
        close = difflib.get_close_matches(name, PRESETS, n=1)
        hint = f" Did you mean {close[0]!r}?" if close else ""
        raise SpecError([("preset", f"unknown preset {name!r}.{hint} Presets: "
                          f"{', '.join(PRESETS)}")])
    return load_spec(SPECS_DIR / f"{name}.toml")


def spec_to_dict(spec: Spec) -> dict[str, Any]:
    """A deep, JSON-ready copy of the validated spec (defaults filled), for manifests."""
    out = copy.deepcopy(dict(spec.data))
    if spec.source is not None:
        out["source"] = spec.source
    return out


# --- lumped parameters --------------------------------------------------------------------------


def lumped_from_spec(spec: Spec, *, model: str | None = None):
    """The :class:`~dtwin.model.lumped.LumpedParameters` a spec implies.

    - Geometry (base radii, centre distance, operating pressure angles, contact ratios, planet
      angles ψ_i + ``imperfections.planet_position_errors``, mesh phases) from
      :class:`~dtwin.model.gears.GearSet`.
    - Masses and inertias from :func:`dtwin.model.gears.masses_and_inertias` (``material.density``)
      unless ``[lumped]`` gives ``m_*``, ``J_*`` or ``Ir2_*`` (``J = Ir2 r²`` with r the base
      radius of sun, ring, planet and the centre distance for the carrier).
    - Mean mesh stiffnesses from ISO 6336-1 (:func:`dtwin.model.stiffness.mesh_stiffness_mean`) unless
      ``mesh.k_sun_planet`` / ``mesh.k_ring_planet`` are given. The load enters through the
      nominal tangential force per planet mesh at the sun's reference circle,
      ``F_t = T_sun / (N r_s)`` with ``T_sun = T_load z_s/(z_s + z_r)`` (ring fixed, no losses;
      the ring mesh carries the same force). With ``load_torque = 0`` the load factor is left out
      (ISO's line load of at least 100 N/mm). The ring's shift is passed to ISO with ISO 21771's
      sign for internal gears (positive towards the tips), i.e. ``−x_ring``.
    - Supports and damping from ``[supports]`` and ``[damping]``; ``lumped.k_u_torsion_*``
      (Lin & Parker's N/m on u = r θ) become ``k_torsion = k_u r²`` and win over ``[supports]``.

    **Arguments:** `spec`; `model`: ``translational`` or ``torsional`` (default ``[model].kind``;
    both use the same parameters, the torsional reduction ignores the translational supports).

    **Returns:** ``LumpedParameters`` (float64).
    """
    import jax.numpy as jnp
    import numpy as np

    kind = model if model is not None else spec["model"]["kind"]
    if kind not in ("translational", "torsional"):
        raise SpecError([("model.kind", f"must be translational or torsional, got {kind!r}")])
    gs = spec.gear_set()
    rb = base_radii(gs)
    a = gs.centre_distance
    a_sp, a_rp = operating_pressure_angles(gs)
    eps_sp, eps_rp = contact_ratios(gs)
    psi = np.asarray(gs.planet_angles)
    err = spec["imperfections"]["planet_position_errors"]
    if err is not None:
        psi = psi + np.asarray(err, dtype=np.float64)

    lum = spec["lumped"]
    geo = masses_and_inertias(gs, density=spec["material"]["density"])
    radius = {"sun": rb[0], "planet": rb[1], "ring": rb[2], "carrier": a}
    vals: dict[str, Any] = {}
    for b in ("sun", "ring", "carrier", "planet"):
        vals[f"m_{b}"] = lum[f"m_{b}"] if lum[f"m_{b}"] is not None else geo[f"m_{b}"]
        if lum[f"J_{b}"] is not None:
            vals[f"J_{b}"] = lum[f"J_{b}"]
        elif lum[f"Ir2_{b}"] is not None:
            vals[f"J_{b}"] = lum[f"Ir2_{b}"] * radius[b] ** 2
        else:
            vals[f"J_{b}"] = geo[f"J_{b}"]

    sup = spec["supports"]
    for b in ("sun", "ring", "carrier"):
        ku = lum[f"k_u_torsion_{b}"]
        vals[f"k_torsion_{b}"] = sup[f"k_torsion_{b}"] if ku is None else ku * radius[b] ** 2
    for b in ("sun", "ring", "carrier", "planet"):
        vals[f"k_bearing_{b}"] = sup[f"k_bearing_{b}"]

    mesh = spec["mesh"]
    k_sp, k_rp = mesh["k_sun_planet"], mesh["k_ring_planet"]
    if k_sp is None or k_rp is None:
        t_load = spec["operating"]["load_torque"]
        ft = None
        if t_load > 0:
            t_sun = t_load * gs.z_sun / (gs.z_sun + gs.z_ring)
            ft = t_sun / (gs.n_planets * reference_radii(gs)[0])
        common = dict(pressure_angle=gs.pressure_angle, tangential_force=ft,
                      K_A=mesh["application_factor"])
        if k_sp is None:
            k_sp = mesh_stiffness_mean(gs.z_sun, gs.z_planet, gs.face_width, eps_sp,
                                       x1=gs.x_sun, x2=gs.x_planet, internal=False, **common)
        if k_rp is None:
            # ISO 6336 / ISO 21771 count an internal gear's shift positive towards its tips
            # (towards the axis): the opposite of dtwin's x_ring (see dtwin.model.gears).
            k_rp = mesh_stiffness_mean(gs.z_planet, gs.z_ring, gs.face_width, eps_rp,
                                       x1=gs.x_planet, x2=-gs.x_ring, internal=True, **common)

    damp = spec["damping"]
    return make_lumped(
        z_sun=gs.z_sun, z_planet=gs.z_planet, z_ring=gs.z_ring, n_planets=gs.n_planets,
        planet_angles=jnp.asarray(psi, dtype=jnp.float64),
        rb_sun=rb[0], rb_planet=rb[1], rb_ring=rb[2], centre_distance=a,
        alpha_sp=a_sp, alpha_rp=a_rp, eps_sp=eps_sp, eps_rp=eps_rp,
        phase0_sp=0.0, phase0_rp=relative_mesh_phase(gs),
        k_sun_planet=k_sp, k_ring_planet=k_rp,
        zeta_sun_planet=damp["zeta_sun_planet"], zeta_ring_planet=damp["zeta_ring_planet"],
        zeta_support=damp["zeta_support"],
        **vals,
    )


def schema_markdown() -> str:
    """Markdown tables of every section of the schema (the field lists of ``docs/spec.md``)."""

    def rows(prefix: str, schema: Mapping[str, FieldSpec]) -> list[str]:
        out = ["| key | unit | default | range / choices | meaning |", "|---|---|---|---|---|"]
        for k, f in schema.items():
            if f.required:
                dflt = "**required**"
            elif f.default is None:
                dflt = "—"
            else:
                dflt = f"`{f.default if not isinstance(f.default, float) else _fmt(f.default)}`"
            if f.choices:
                rng = " \\| ".join(f.choices)
            else:
                lo, hi = f.range()
                rng = f"{_fmt(lo) if lo is not None else ''} … {_fmt(hi) if hi is not None else ''}"
            reg = f" (registry `{f.registry}`)" if f.registry else ""
            out.append(f"| `{k}` | {f.unit or '—'} | {dflt} | {rng} | {f.doc}{reg} |")
        return out

    parts = []
    for section, schema in SCHEMA.items():
        parts += [f"### `[{section}]`", ""] + rows(section, schema) + [""]
    parts += ["### `[operating.speed_profile]` (optional)", ""] + rows(
        "operating.speed_profile", SPEED_PROFILE_SCHEMA) + [""]
    parts += ["### `[[faults]]` (array of tables, any number)", ""] + rows(
        "faults", FAULT_SCHEMA) + [""]
    parts += ["### `[bearings.sun]`, `[bearings.planet]`, `[bearings.carrier]` (optional)", ""]
    parts += rows("bearings", BEARING_SCHEMA) + [""]
    return "\n".join(parts)


__all__ = [
    "PRESETS",
    "SCHEMA",
    "SPECS_DIR",
    "FieldSpec",
    "Spec",
    "load_spec",
    "lumped_from_spec",
    "preset",
    "schema_markdown",
    "spec_to_dict",
]
