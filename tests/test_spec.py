"""Tests of dtwin.spec: schema validation, presets, lumped parameters from a spec."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest

from dtwin.errors import SpecError, UnreadableFileError
from dtwin.spec import (
    PRESETS,
    SCHEMA,
    load_spec,
    lumped_from_spec,
    preset,
    spec_to_dict,
)

pytestmark = pytest.mark.filterwarnings("ignore:z_ring = 84")

DOCS = Path(__file__).resolve().parent.parent / "docs" / "spec.md"

MINIMAL = {
    "gears": {"z_sun": 21, "z_planet": 30, "z_ring": 81, "n_planets": 3, "module": 0.002,
              "face_width": 0.02},
    "operating": {"f_sun": 30.0, "load_torque": 50.0},
}


def _with(path: str, value, base=MINIMAL):
    """A copy of `base` with the dotted `path` set (``faults`` takes a list of tables)."""
    spec = copy.deepcopy(base)
    *parents, key = path.split(".")
    node = spec
    for p in parents:
        node = node.setdefault(p, {})
    node[key] = value
    return spec


def _problems(raw) -> list[tuple[str, str]]:
    with pytest.raises(SpecError) as e:
        load_spec(raw)
    return e.value.problems


# --- presets -------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", PRESETS)
def test_presets_load(name):
    s = preset(name)
    assert s.name == name
    json.dumps(spec_to_dict(s))  # JSON-ready for manifests
    # a loaded spec round-trips through its dict form unchanged
    d = spec_to_dict(s)
    d.pop("source")
    assert spec_to_dict(load_spec(d)) | {"source": s.source} == spec_to_dict(s)


def test_paper_presets_state_the_paper_operating_points():
    # paper: motor 1800 rpm -> 30 Hz (simulation); bench measured 1782 rpm -> 29.7 Hz
    assert preset("paper-sim")["operating"]["f_sun"] == pytest.approx(1800 / 60)
    assert preset("paper-bench")["operating"]["f_sun"] == pytest.approx(1782 / 60)
    bench = preset("paper-bench").gear_set()
    assert float(bench.centre_distance) == pytest.approx(0.0525)
    # the preset's comment states the derived operating pressure angles: 21.45° and 18.44°
    from dtwin.model.gears import operating_pressure_angles

    a_sp, a_rp = operating_pressure_angles(bench)
    assert math.degrees(float(a_sp)) == pytest.approx(21.45, abs=0.01)
    assert math.degrees(float(a_rp)) == pytest.approx(18.44, abs=0.01)


def test_unknown_preset_suggests_a_name():
    with pytest.raises(SpecError, match="paper-sim"):
        preset("paper_sim")


# --- Lin & Parker --------------------------------------------------------------------------------

def test_lin_parker_preset_gives_their_lumped_values():
    """Lin & Parker (1999) Table 1, docs/references.md §3: m, I/r², k in their u = r θ terms."""
    lp = lumped_from_spec(preset("lin-parker"))
    r = {"sun": lp.rb_sun, "ring": lp.rb_ring, "planet": lp.rb_planet,
         "carrier": lp.centre_distance}
    masses = {"sun": 0.4, "ring": 2.35, "carrier": 5.43, "planet": 0.66}
    ir2 = {"sun": 0.39, "ring": 3.0, "carrier": 6.29, "planet": 0.61}
    for b in masses:
        assert float(getattr(lp, f"m_{b}")) == pytest.approx(masses[b], rel=1e-12)
        assert float(getattr(lp, f"J_{b}") / r[b] ** 2) == pytest.approx(ir2[b], rel=1e-12)
    assert float(lp.k_sun_planet) == float(lp.k_ring_planet) == 5e8
    for b in ("sun", "ring", "carrier", "planet"):
        assert float(getattr(lp, f"k_bearing_{b}")) == 1e8
    assert float(lp.k_torsion_ring / lp.rb_ring**2) == pytest.approx(1e9, rel=1e-12)
    assert float(lp.k_torsion_sun) == float(lp.k_torsion_carrier) == 0.0
    assert math.degrees(float(lp.alpha_sp)) == pytest.approx(24.6, abs=1e-9)
    assert math.degrees(float(lp.alpha_rp)) == pytest.approx(24.6, abs=1e-9)


def test_lin_parker_preset_reproduces_their_natural_frequencies():
    """Lin & Parker (1999) Table 2 (docs/references.md §3), N = 3, within 0.5 %."""
    from dtwin.model.modal import natural_frequencies

    f = np.sort(np.asarray(natural_frequencies(lumped_from_spec(preset("lin-parker")))))
    rot = [1475.7, 1930.3, 2658.3, 7462.8, 11775.3]
    trans = [743.2, 1102.4, 1896.0, 2276.4, 6986.3, 9647.9]
    expected = np.sort(np.array([0.0] + rot + trans + trans))
    assert f.shape == expected.shape
    assert abs(f[0]) < 1.0
    np.testing.assert_allclose(f[1:], expected[1:], rtol=5e-3)


# --- lumped parameters from geometry ----------------------------------------------------------------

def _iso_mesh_stiffness(z1, z2, b, eps, ft, internal=False, x1=0.0, x2=0.0):
    """ISO 6336-1 method B by hand (docs/references.md §4), 20°, h_fP/m = 1.25, K_A = 1."""
    inv_zn2 = 0.0 if internal else 1.0 / z2
    q = (0.04723 + 0.15551 / z1 + 0.25791 * inv_zn2 - 0.00635 * x1 - 0.11654 * x1 / z1
         - 0.00193 * x2 - 0.24188 * x2 * inv_zn2 + 0.00529 * x1**2 + 0.00182 * x2**2)
    c_b = (1 + 0.5 * (1.2 - 1.25)) * 1.0
    line_load = ft / (b * 1e3)  # N/mm
    c_single = (1 / q) * 0.8 * 1.0 * c_b * min(line_load / 100.0, 1.0) ** 0.25  # N/(mm µm)
    c_gamma = c_single * (0.75 * eps + 0.25)
    return c_gamma * (b * 1e3) * 1e6  # N/µm -> N/m


def test_iso_mesh_stiffness_from_the_load_torque():
    s = preset("paper-sim")
    lp = lumped_from_spec(s)
    # T_sun = T_carrier Zs/(Zs+Zr); F_t = T_sun/(N r_sun) per planet mesh
    ft = 50.0 * 21 / 102 / (3 * 0.021)
    k_sp = _iso_mesh_stiffness(21, 30, 0.02, float(lp.eps_sp), ft)
    k_rp = _iso_mesh_stiffness(30, 81, 0.02, float(lp.eps_rp), ft, internal=True)
    assert float(lp.k_sun_planet) == pytest.approx(k_sp, rel=1e-10)
    assert float(lp.k_ring_planet) == pytest.approx(k_rp, rel=1e-10)
    # "a few 1e8 N/m" for module-2 steel gears of 20 mm face (docs/references.md §4)
    assert 1e8 < float(lp.k_sun_planet) < 1e9
    # no load: the load factor is left out (line load >= 100 N/mm)
    lp0 = lumped_from_spec(load_spec(_with("operating.load_torque", 0.0)))
    k0 = _iso_mesh_stiffness(21, 30, 0.02, float(lp0.eps_sp), 1e9)
    assert float(lp0.k_sun_planet) == pytest.approx(k0, rel=1e-10)


def test_iso_mesh_stiffness_of_the_shifted_bench():
    # x_sun = +0.2588 on the pinion; the ring's -0.2408 (dtwin sign) is +0.2408 in ISO 21771's
    # sign for internal gears (positive towards the tips)
    s = preset("paper-bench")
    lp = lumped_from_spec(s)
    gs = s.gear_set()
    ft = 50.0 * 21 / 105 / (3 * 0.021)
    k_sp = _iso_mesh_stiffness(21, 31, 0.02, float(lp.eps_sp), ft, x1=float(gs.x_sun))
    k_rp = _iso_mesh_stiffness(31, 84, 0.02, float(lp.eps_rp), ft, internal=True,
                               x2=-float(gs.x_ring))
    assert float(lp.k_sun_planet) == pytest.approx(k_sp, rel=1e-10)
    assert float(lp.k_ring_planet) == pytest.approx(k_rp, rel=1e-10)


def test_geometry_fields_and_overrides():
    raw = _with("lumped", {"m_sun": 1.5, "J_planet": 2e-3})
    raw["mesh"] = {"k_sun_planet": 3e8}
    raw["damping"] = {"zeta_mesh": 0.05}
    raw["imperfections"] = {"planet_position_errors": [0.0, 0.01, -0.01]}
    lp = lumped_from_spec(load_spec(raw))
    assert float(lp.m_sun) == 1.5 and float(lp.J_planet) == 2e-3
    assert float(lp.k_sun_planet) == 3e8
    assert float(lp.zeta_sun_planet) == float(lp.zeta_ring_planet) == 0.05
    np.testing.assert_allclose(lp.planet_angles,
                               2 * np.pi * np.arange(3) / 3 + np.array([0.0, 0.01, -0.01]))
    # the rest from the geometry: base radii m z cos α / 2, a = 51 mm, steel disc of the sun
    assert float(lp.rb_sun) == pytest.approx(0.021 * math.cos(math.radians(20)), rel=1e-12)
    assert float(lp.centre_distance) == pytest.approx(0.051, rel=1e-12)
    assert float(lp.m_planet) == pytest.approx(7850 * math.pi * 0.03**2 * 0.02, rel=1e-12)


def test_model_argument_checked():
    with pytest.raises(SpecError, match="model.kind"):
        lumped_from_spec(load_spec(MINIMAL), model="modal")


# --- validation --------------------------------------------------------------------------------

BAD = [
    # (path, value, field named in the error, text in the message)
    ("gears.module", 2, "gears.module", "did you mean 2 mm = 0.002 m?"),
    ("gears.pressure_angle", 20, "gears.pressure_angle", "did you mean 20° = 0.349066 rad?"),
    ("gears.face_width", 20.0, "gears.face_width", "did you mean 20 mm = 0.02 m?"),
    ("gears.z_sun", 21.5, "gears.z_sun", "integer"),
    ("gears.n_planets", 5, "gears.n_planets", "do not fit"),  # tip circles overlap
    ("gears.modul", 0.002, "gears.modul", "did you mean 'module'"),
    ("calibration.heldout_gap_db", -2.0, "calibration.heldout_gap_db", "outside"),
    ("sensor.frf_hz", [100.0, 10.0], "sensor.frf_hz", "increasing"),
    ("sensor.frf_db", [0.0], "sensor.frf_db", "one gain per knot"),
    ("gears.planet_angles", [0.0, 2.0], "gears.planet_angles", "3 finite angles"),
    ("material.youngs_modulus", 206.0, "material.youngs_modulus", "206 GPa"),
    ("material.density", 7.85, "material.density", "7.85 g/cm³"),
    ("material.poisson", 0.7, "material.poisson", "outside"),
    ("mesh.k_sun_planet", 300.0, "mesh.k_sun_planet", "300 N/µm"),
    ("mesh.te_amplitude", 20.0, "mesh.te_amplitude", "20 µm"),
    ("mesh.te_harmonics", [1.0, "a"], "mesh.te_harmonics[1]", "number"),
    ("mesh.n_harmonics", 0, "mesh.n_harmonics", "outside"),
    ("supports.k_bearing_sun", -1.0, "supports.k_bearing_sun", "outside"),
    ("supports.k_torsion_ring", "stiff", "supports.k_torsion_ring", "number"),
    ("damping.zeta_support", 3.0, "damping.zeta_support", "outside"),
    ("lumped.m_sun", 400.0, None, None),  # plausible (a big sun) -> no error
    ("lumped.J_sun", float("nan"), "lumped.J_sun", "finite"),
    ("operating.f_sun", 1800.0, "operating.f_sun", "1800 rpm = 30 Hz"),
    ("operating.load_torque", -5.0, "operating.load_torque", "outside"),
    ("operating.speed_profile", {"t": [0.0, 1.0, 0.5], "f_sun": [0.0, 30.0, 30.0]},
     "operating.speed_profile.t", "increase"),
    ("sensor.quantity", "accel", "sensor.quantity", "'acceleration'"),
    ("sensor.sample_rate", 5e7, "sensor.sample_rate", "outside"),
    ("sensor.window", "hanning", "sensor.window", "'hann'"),
    ("sensor.angle", 90.0, "sensor.angle", "90° = 1.5708 rad"),
    ("imperfections.load_sharing", [1.0, 1.0], "imperfections.load_sharing", "one value per"),
    ("imperfections.sun_eccentricity", 0.05, "imperfections.sun_eccentricity",
     "0.05 mm = 5e-05 m"),
    ("motor.pmsm.pole_pairs", "four", "motor.pmsm.pole_pairs", "must be a number"),
    ("motor.pmsm.L_d", 5.0, "motor.pmsm.L_d", "H (not mH)"),
    ("motor.type", "dc", "motor.type", "one of"),
    ("model.kind", "rigid", "model.kind", "translational"),
    ("bearings.sun", {"n_rolling_elements": 9, "ball_diameter": 0.05, "pitch_diameter": 0.04},
     "bearings.sun.ball_diameter", "smaller"),
    ("bearings.ring", {"n_rolling_elements": 9}, "bearings.ring", "allowed: sun, planet"),
    ("faults", [{"location": "sun", "type": "missing_tooth", "severity": 1.5}],
     "faults[0].severity", "outside"),
    ("faults", [{"location": "sun", "type": "missing_tooth", "severity": 0.5, "tooth": 21}],
     "faults[0].tooth", "0..20"),
    ("faults", [{"location": "planet", "type": "pitting", "severity": 0.5, "planet": 3}],
     "faults[0].planet", "0..2"),
    ("faults", [{"location": "sun", "type": "pitting", "severity": 0.5, "flank": "ring"}],
     "faults[0].flank", "only planet"),
    ("faults", [{"location": "sun", "type": "chipped", "severity": 0.5}],
     "faults[0].type", "one of"),
    ("faults", [{"type": "crack", "severity": 0.5}], "faults[0].location", "required"),
    ("gearz", {}, "gearz", "did you mean 'gears'"),
]


@pytest.mark.parametrize("path, value, field, text", BAD, ids=[b[0] for b in BAD])
def test_bad_values_name_the_field(path, value, field, text):
    raw = _with(path, value)
    if field is None:
        load_spec(raw)  # a plausible value is accepted
        return
    problems = _problems(raw)
    fields = [p for p, _ in problems]
    assert field in fields, problems
    msg = dict(problems)[field]
    assert text in msg, msg


def test_every_section_is_validated():
    # each schema section has at least one bad-value case above
    covered = {b[0].split(".")[0] for b in BAD if b[2] is not None}
    assert set(SCHEMA) | {"faults", "bearings"} <= covered


def test_all_problems_are_collected_in_one_error():
    raw = _with("gears.module", 2)
    raw = _with("operating.f_sun", 1800.0, raw)
    raw = _with("sensor.quantity", "g", raw)
    raw["damping"] = {"zeta_mesh": 0.05, "zeta_sun_planet": 0.1}
    raw["lumped"] = {"J_sun": 1e-4, "Ir2_sun": 0.3}
    fields = [p for p, _ in _problems(raw)]
    for f in ("gears.module", "operating.f_sun", "sensor.quantity", "damping.zeta_sun_planet",
              "lumped.Ir2_sun"):
        assert f in fields
    # and the message of the one error lists them all
    with pytest.raises(SpecError) as e:
        load_spec(raw)
    assert str(e.value).count("\n") >= 4


def test_missing_required_fields():
    fields = [p for p, _ in _problems({"gears": {"z_sun": 21}})]
    for f in ("gears.z_planet", "gears.z_ring", "gears.n_planets", "gears.module",
              "gears.face_width"):
        assert f in fields


def test_defaults_are_filled():
    s = load_spec(MINIMAL)
    assert s["gears"]["pressure_angle"] == pytest.approx(math.radians(20))
    assert s["damping"]["zeta_sun_planet"] == 0.07  # docs/references.md §4 typical mesh damping
    assert s["sensor"]["angle"] == pytest.approx(math.pi / 2)  # conventions: on top
    assert s["motor"] == {"type": "ideal"}
    assert s["faults"] == [] and s["bearings"] == {}
    raw = _with("motor", {"type": "pmsm", "pmsm": {"pole_pairs": 4, "R_s": 0.5}})
    assert load_spec(raw)["motor"] == {"type": "pmsm", "pmsm": {"pole_pairs": 4, "R_s": 0.5}}


def test_files(tmp_path):
    p = tmp_path / "box.toml"
    p.write_text('[gears]\nz_sun = 21\nz_planet = 30\nz_ring = 81\nn_planets = 3\n'
                 'module = 0.002\nface_width = 0.02\n[[faults]]\nlocation = "sun"\n'
                 'type = "missing_tooth"\nseverity = 1.0\ntooth = 3\n')
    s = load_spec(p)
    assert s.source == str(p)
    assert s["faults"][0]["tooth"] == 3 and s["faults"][0]["flank"] is None
    bad = tmp_path / "bad.toml"
    bad.write_text("[gears\nz_sun = 21\n")
    with pytest.raises(SpecError, match="not valid TOML"):
        load_spec(bad)
    with pytest.raises(UnreadableFileError, match="does not exist"):
        load_spec(tmp_path / "missing.toml")


def test_docs_describe_every_field():
    text = DOCS.read_text()
    for section, schema in SCHEMA.items():
        assert f"[{section}]" in text, section
        for key in schema:
            assert f"`{key}`" in text, f"{section}.{key}"
