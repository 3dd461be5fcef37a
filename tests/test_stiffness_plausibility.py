"""A fitted mesh stiffness that no steel gear pair of the spec's geometry can have is flagged
NOT DETERMINED (dtwin.identify.plausibility).

References outside the code: ISO 6336-1:2006, clause 9, method B (the mean mesh stiffness
``c_γα b`` of a steel spur pair, 5–25 N/(mm·µm) per unit face width), and the independent
simulator's stated mean mesh stiffnesses (``../shared/independent/machines/*/truth.json``:
2.88e8 and 3.84e8 N/m for the 19/38/95 set), which lie within the check's factor of 3 of the ISO
value, while `dtwin identify --free k_sun_planet,zeta_mesh,sun_fault` on that machine's
sun-fault record fitted 1.83e7 N/m with an "ok" interval [1.57e7, 2.12e7] before the check.
"""

from __future__ import annotations

import numpy as np
import pytest

from dtwin.identify.params import ParameterSet
from dtwin.identify.plausibility import (
    ISO_FACTOR,
    flag_implausible,
    implausible_stiffness,
    iso_mesh_stiffness,
)
from dtwin.identify.uncertainty import analyse
from dtwin.spec import load_spec, preset, spec_to_dict

MCFADDEN = dict(gears=dict(z_sun=19, z_planet=38, z_ring=95, n_planets=3, module=0.002,
                           pressure_angle=0.3490658503988659, face_width=0.02),
                operating=dict(f_sun=25.0, load_torque=60.0),
                sensor=dict(sample_rate=10240.0))


def test_iso_value_is_a_steel_pairs_and_ignores_the_specs_own_stiffness():
    spec = preset("paper-bench")
    iso = iso_mesh_stiffness(spec)
    # ISO 6336-1: c'_th of standard steel pairs 12–17 N/(mm µm), times C_M = 0.8 and a light
    # load's reduction (F_t/b below 100 N/mm), times 0.75 eps + 0.25 (eps 1.5–2): c_γα of a
    # steel pair lies within 5–25 N/(mm µm); face width 20 mm
    for k in iso.values():
        assert 5e9 * 0.02 < k < 25e9 * 0.02
    d = spec_to_dict(spec)
    d.pop("source", None)
    d["mesh"]["k_sun_planet"] = 1e6
    assert iso_mesh_stiffness(load_spec(d)) == pytest.approx(iso, rel=1e-12)
    # another material: c' scales with E (ISO 6336-1, clause 9); a polymer pair (E = 3 GPa)
    d["material"]["youngs_modulus"] = 3e9
    polymer = iso_mesh_stiffness(load_spec(d))
    assert polymer["k_sun_planet"] == pytest.approx(iso["k_sun_planet"] * 3e9 / 2.06e11, rel=1e-9)
    assert not implausible_stiffness({"k_sun_planet": polymer["k_sun_planet"]}, load_spec(d))


def test_the_independent_simulators_stiffness_passes_and_the_bent_fit_is_flagged():
    spec = load_spec(MCFADDEN)
    assert implausible_stiffness({"k_sun_planet": 2.88e8, "k_ring_planet": 3.84e8}, spec) == {}
    flags = implausible_stiffness({"k_sun_planet": 1.8251e7, "sun_fault": 0.29}, spec)
    assert list(flags) == ["k_sun_planet"]
    assert "ISO 6336-1" in flags["k_sun_planet"] and "indicative" in flags["k_sun_planet"]
    iso = iso_mesh_stiffness(spec)["k_sun_planet"]
    assert implausible_stiffness({"k_sun_planet": iso * ISO_FACTOR * 1.01}, spec)
    assert not implausible_stiffness({"k_sun_planet": iso * ISO_FACTOR * 0.99}, spec)
    assert implausible_stiffness({"k_sun_planet": 1e6}, None) == {}


def test_the_flag_enters_the_fits_uncertainty():
    rng = np.random.default_rng(0)
    m = 60
    x, y = rng.normal(size=m), rng.normal(size=m)
    pset = ParameterSet.build(["k_sun_planet", "sun_fault"],
                              initial={"k_sun_planet": 1.8e7, "sun_fault": 0.3})
    unc = analyse(pset, np.zeros(2), 0.1 * rng.normal(size=m), np.column_stack([x, y]),
                  np.arange(m))
    assert unc.not_determined == {}
    flagged = flag_implausible(unc, pset.as_dict(np.zeros(2)), load_spec(MCFADDEN))
    assert sorted(flagged.not_determined) == ["k_sun_planet", "sun_fault"]
    assert "ISO 6336-1" in flagged.not_determined["k_sun_planet"]
    assert flagged.not_determined["sun_fault"].startswith(
        "fitted beside an implausible mesh stiffness (k_sun_planet)")
    assert unc.not_determined == {}  # the input is not modified
    plausible = flag_implausible(unc, {"k_sun_planet": 2.0e8, "sun_fault": 0.3},
                                 load_spec(MCFADDEN))
    assert plausible.not_determined == {}
