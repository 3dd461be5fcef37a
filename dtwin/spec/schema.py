"""The spec's schema: every section's fields with their unit, default, plausible range or
choices and meaning (:class:`FieldSpec`, :data:`SCHEMA` and the tables of ``[[faults]]``,
``[bearings.*]`` and ``[operating.speed_profile]``), and the Markdown of ``docs/spec.md``'s
field lists (:func:`schema_markdown`). Registered parameters (:mod:`dtwin.model.registry`) take
the registry's plausible range."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

from ..model.registry import REGISTRY

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
        "contact_margin": FieldSpec("float", "1", None, -1e6, 1e6,
                                    doc="the calibrated twin's least mesh deflection over its "
                                        "records, over its mean (written by dtwin calibrate; "
                                        "below 0 its teeth part every mesh cycle: a healthy "
                                        "loaded gearbox's do not)"),
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


def _fmt(v: float) -> str:
    return f"{v:.6g}"


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
