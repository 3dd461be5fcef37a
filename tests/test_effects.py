"""The parts and candidates added for discovery (issue 8): planet-bearing defects, a housing
resonance, the time-varying transfer path. Cheap checks against closed forms and published
numbers; the workflow itself is exercised in tests/test_discover_workflow.py."""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from dtwin.identify.discover import effects as E
from dtwin.identify.discover.effects.base import EffectContext
from dtwin.identify.discover.effects.transfer_path import locate_resonance
from dtwin.identify.lines import Kinematics
from dtwin.model.parts.bearing_defect import PlanetBearingDefect, bearing_frequencies
from dtwin.model.parts.housing_resonance import HousingResonance, resonance_gain
from dtwin.model.twin import Coords
from dtwin.spec import load_spec, preset, spec_to_dict
from dtwin.spec.build import build_twin

GEOMETRY = dict(n_rolling_elements=13, ball_diameter=0.005, pitch_diameter=0.025)


def test_bearing_frequencies_cwru_6205():
    # SKF 6205-2RS (CWRU bearing data centre): 9 balls, d = 7.94 mm, D = 39.04 mm; defect
    # frequencies in orders of the shaft: BPFO 3.5848, BPFI 5.4152, FTF 0.39828, BSF 2.357
    f = bearing_frequencies(9, 0.00794, 0.03904)
    assert f["bpfo"] == pytest.approx(3.5848, abs=2e-4)
    assert f["bpfi"] == pytest.approx(5.4152, abs=2e-4)
    assert f["ftf"] == pytest.approx(0.39828, abs=1e-4)
    assert f["bsf"] == pytest.approx(2.357, abs=2e-3)
    # identities: BPFO + BPFI = n f_r; cage seen from both races adds to f_r
    assert f["bpfo"] + f["bpfi"] == pytest.approx(9.0)
    assert f["ftf"] + f["cage"] == pytest.approx(1.0)


def test_bearing_defect_zero_is_absent_and_linear():
    tw = build_twin(preset("paper-sim"), kind="torsional")
    q = Coords.zeros(tw.n_planets).set(theta_p=jnp.array([-0.3, 0.1, 0.2]), theta_c=jnp.asarray(0.05))
    m0 = PlanetBearingDefect(jnp.asarray(0.0), defect_order=5.2, modulation_order=1.0).modulation(
        tw, 0.0, q, q)
    assert float(jnp.max(jnp.abs(m0.e_sp))) == 0.0
    m1 = PlanetBearingDefect(jnp.asarray(1e-7), defect_order=5.2, modulation_order=1.0)
    m2 = PlanetBearingDefect(jnp.asarray(2e-7), defect_order=5.2, modulation_order=1.0)
    e1, e2 = m1.modulation(tw, 0.0, q, q), m2.modulation(tw, 0.0, q, q)
    np.testing.assert_allclose(e2.e_sp, 2 * e1.e_sp, rtol=1e-12)
    assert float(e1.e_sp[1]) == 0.0 and float(e1.e_sp[0]) != 0.0  # planet 0 only
    np.testing.assert_array_equal(e1.e_sp, e1.e_rp)  # relieves both meshes


def test_bearing_pulse_is_zero_mean():
    # the pulse train minus its mean: the defect does not move the static deflection
    spin = np.linspace(0, 2 * np.pi, 4001)[:-1]
    k = 8
    p = (0.5 * (1 + np.cos(spin))) ** k - math.comb(2 * k, k) / 4**k
    assert abs(np.mean(p)) < 1e-12


def test_resonance_gain_closed_form():
    f = np.array([0.0, 1450.0, 1e6])
    g = np.asarray(resonance_gain(f, 1450.0, 0.05, 1.0))
    assert g[0] == pytest.approx(1.0)
    assert g[1] == pytest.approx(1 / (2 * 0.05))
    assert g[2] < 1e-5
    assert np.asarray(resonance_gain(f, 1450.0, 0.05, 0.0)) == pytest.approx(1.0)


def test_housing_resonance_zero_gain_adds_nothing():
    tw = build_twin(preset("paper-sim"), kind="torsional")
    part = HousingResonance(jnp.asarray(0.0))
    assert part.aux_size == 2
    # acceleration is gain × (x − s): zero at zero gain whatever the states
    q = Coords.zeros(tw.n_planets)
    mesh = tw.mesh_state(0.0, q, q, tw.modulation(0.0, q, q))
    assert float(part.acceleration(tw, 0.0, q, q, q, mesh, jnp.array([3.0, 1.0]))) == 0.0


def test_locate_resonance_recovers_frequency():
    f = np.arange(200.0, 2400.0, 37.0)
    ex = 20 * np.log10(np.asarray(resonance_gain(f, 1450.0, 0.05, 0.6))) + 2.0
    f_res, zeta, g = locate_resonance(f, ex, 2500.0)
    assert f_res == pytest.approx(1450.0, rel=0.01)
    assert zeta == 0.05
    assert g == pytest.approx(0.6, abs=0.06)
    assert locate_resonance(f, np.zeros_like(f), 2500.0) is None  # nothing to explain


def test_located_resonance_amplifies_the_models_own_lines():
    """A resonance located against a model that carries lines off the mesh grid (a fault's
    comb, once the fault is in the model) counts those lines in its signature: the mode lifts
    every line of the model in its band. A line only the measurement has (a tone) stays out."""
    spec = load_spec(_spec())
    tw = build_twin(spec, kind="torsional")
    kin = Kinematics.from_spec(spec)
    freqs = np.arange(0.0, 2500.0, 0.25)
    floor = np.full_like(freqs, 1e-4)
    model = floor.copy()
    grid = [m * kin.f_mesh + n * kin.f_carrier for m in range(1, 5) for n in range(-8, 9)]
    grid = [f for f in grid if 0 < f < 2500.0]
    comb = [k * kin.f_sun_fault + n * kin.f_carrier for k in range(1, 40) for n in (-1, 1)]
    comb = [f for f in comb if 1200.0 < f < 1700.0 and min(abs(np.array(grid) - f)) > 1.0]
    for f in grid:
        model[int(round(f / 0.25))] = 1.0
    for f in comb:
        model[int(round(f / 0.25))] = 0.05
    measured = model * np.abs(1.0 + 0.6 * (np.asarray(resonance_gain(freqs, 1450.0, 0.05, 1.0))
                                           - 1.0)) * 1.3
    # a tone in the band, off the grid and the comb
    every = np.array(grid + comb)
    tone = next(f for f in np.arange(1400.0, 1500.0, 0.25) if np.min(np.abs(every - f)) > 2.0)
    measured[int(round(tone / 0.25))] = 0.5
    ctx = EffectContext(spec, tw, kin, freqs=freqs, measured=measured, model=model,
                        floor=floor)
    e = E.HousingResonanceEffect().adapt(ctx)
    assert e is not None and e.f_res == pytest.approx(1450.0, rel=0.01)
    lo, hi = e.f_res * (1 - 3 * e.zeta), e.f_res * (1 + 3 * e.zeta)
    sig = np.array([s.frequency for s in e.signature(kin, 2500.0)])
    inside = [f for f in comb if lo <= f <= hi]
    assert inside and all(np.min(np.abs(sig - f)) <= 0.25 for f in inside)
    assert all(lo <= f <= hi for f in e.model_lines)
    assert np.min(np.abs(sig - tone)) > 1.0
    # the grid lines are not listed twice
    assert len(sig) == len(np.unique(np.round(sig, 6)))
    assert e.summary == f"housing resonance at {e.f_res:.1f} Hz, damping ratio {e.zeta:g}"


def _spec(**sensor):
    d = spec_to_dict(preset("paper-sim"))
    d.pop("source", None)
    d["sensor"].update(sensor)
    return d


def test_adapt_withdraws_and_specialises():
    spec = load_spec(_spec())
    tw = build_twin(spec, kind="torsional")
    kin = Kinematics.from_spec(spec)
    ctx = EffectContext(spec, tw, kin)
    # no [bearings.planet]: bearing candidates withdrawn; a windowed base: no time-varying path
    assert E.PlanetBearingEffect(race="outer").adapt(ctx) is None
    assert E.TimeVaryingPathEffect().adapt(ctx) is None
    assert E.HousingResonanceEffect().adapt(ctx) is None  # no data, no resonance
    d = _spec(window_exponent=0.0)
    d["bearings"] = {"planet": GEOMETRY}
    spec2 = load_spec(d)
    ctx2 = EffectContext(spec2, build_twin(spec2, kind="torsional"), kin)
    b = E.PlanetBearingEffect(race="outer").adapt(ctx2)
    assert b is not None and b.geometry == (13, 0.005, 0.025, 0.0)
    d_ord, m_ord = b.orders()
    assert d_ord == pytest.approx(13 / 2 * 0.8) and m_ord == 1.0
    sig = b.signature(kin, 2500.0)
    f_bpfo = d_ord * kin.f_planet_fault
    assert any(abs(s.frequency - f_bpfo) < 1e-9 and s.label == "BPFO" for s in sig)
    # a rolling-element defect strikes at 2 BSF: its harmonics are labelled in BSF multiples
    # ("4BSF" at twice the impact rate, not "22BSF", which reads as 22 BSF)
    ball = E.PlanetBearingEffect(race="ball").adapt(ctx2)
    f_bsf = bearing_frequencies(*ball.geometry)["bsf"] * kin.f_planet_fault
    sig = {s.label: s.frequency for s in ball.signature(kin, 2500.0)}
    assert sig["2BSF"] == pytest.approx(2 * f_bsf) and sig["4BSF"] == pytest.approx(4 * f_bsf)
    assert not any("22BSF" in lab or "32BSF" in lab for lab in sig)
    inner = E.PlanetBearingEffect(race="inner").adapt(ctx2)
    assert any(s.label == "2BPFI" for s in inner.signature(kin, 2500.0))
    assert E.TimeVaryingPathEffect().adapt(ctx2) is not None
    # every library effect documents its typical range
    for e in E.registered_effects():
        lo, hi = e.typical_range
        assert 0 < lo < hi and e.typical_note and e.main_name, e


def test_time_varying_path_signature_is_allowed_lines():
    kin = Kinematics.from_spec(preset("paper-sim"))
    sig = E.TimeVaryingPathEffect().signature(kin, 2500.0)
    assert sig
    for s in sig:
        m = round(s.frequency / kin.f_mesh)
        n = round((s.frequency - m * kin.f_mesh) / kin.f_carrier)
        assert kin.allowed_by_sideband_rule(m, n) and n != 0


def test_window_mean_closed_form():
    from dtwin.identify.discover.effects.transfer_path import window_mean

    phi = np.linspace(0, 2 * np.pi, 20001)[:-1]
    for p in (0.0, 1.0, 4.0, 2.5):
        assert window_mean(p) == pytest.approx(np.mean((0.5 * (1 + np.cos(phi))) ** p), rel=1e-9)


def test_mount_path_is_its_line_and_nothing_else():
    """The housing-on-mounts path adds exactly ``a cos(2 pi f t) + b sin(2 pi f t)`` to the
    sensor's acceleration, whatever the gear set does; with both amplitudes zero the twin stays
    periodic at constant speed, with either nonzero it does not (a line at f_x is not a gearbox
    frequency). The located modulation's flat-path scale is the closed form
    ``c_0 Zr / ((Zs + Zr) r_b,ring m_ring)``."""
    from dtwin.identify.discover.effects.modulation import _flat_path
    from dtwin.model.parts.mount_path import MountPath
    from dtwin.model.parts.transfer_path import PlanetPassTransferPath, window_cosine_coefficients
    from dtwin.simulation.periodic import hunting_cycles, periodic_reason

    tw = build_twin(preset("paper-sim"), kind="torsional")
    part = MountPath(jnp.asarray(0.3), jnp.asarray(-0.2), f=2.1)
    q = Coords.zeros(tw.n_planets)
    mesh = tw.mesh_state(0.0, q, q, tw.modulation(0.0, q, q))
    for t in (0.0, 0.1, 0.37):
        a = float(part.acceleration(tw, t, q, q, q, mesh, jnp.zeros(0)))
        assert a == pytest.approx(0.3 * math.cos(2 * math.pi * 2.1 * t)
                                  - 0.2 * math.sin(2 * math.pi * 2.1 * t), abs=1e-15)
    assert part.aux_size == 0
    assert hunting_cycles(tw.with_parts(MountPath(jnp.asarray(0.0), jnp.asarray(0.0), f=2.1))) \
        == hunting_cycles(tw)
    assert "mount path" in periodic_reason(tw.with_parts(part))
    path = next(p for p in tw.parts if isinstance(p, PlanetPassTransferPath))
    c0 = (float(path.window_harmonics[0]) if path.window_harmonics is not None
          else float(window_cosine_coefficients(float(path.window_exponent), 1)[0]))
    lp = tw.lp
    want = c0 * float(path.force_weight) * lp.z_ring / (lp.z_sun + lp.z_ring) / (
        float(lp.rb_ring) * float(lp.m_ring))
    assert _flat_path(tw) == pytest.approx(want, rel=1e-12)


def test_planet_position_effect_is_the_spec_planets():
    """The planet-position member's part (mesh phases only, load shared equally) and a spec's
    ``imperfections.planet_position_errors`` (the planets moved on the carrier,
    ``dtwin.spec.lumped_from_spec``) are the same planets: the forbidden sidebands
    ``m fm ± n fc`` (m = 1…4, n = 1, 2) of the two twins agree within 0.3 dB (the spec also moves
    each planet's sensor window by its error, ~1e-3 of the window's width). With the pins'
    offsets loading the meshes (``pin_offset=True``, no floating member) the same errors move
    these lines by 7–20 dB (1 s records): not the same machine."""
    from dtwin.model.parts.imperfections import PlanetPositionErrors
    from dtwin.signal.spectrum import amplitude_spectrum
    from dtwin.simulation.simulate import simulate
    from dtwin.spec.build import daq_from_spec

    err = [0.0, 4e-4, -3e-4]  # rad: 0, +20, -15 µm at the pin
    d = spec_to_dict(preset("paper-sim"))
    d.pop("source", None)
    d["imperfections"]["planet_position_errors"] = err
    base = build_twin(preset("paper-sim"), kind="torsional")
    kin = Kinematics.from_spec(preset("paper-sim"))
    daq = daq_from_spec(preset("paper-sim"), snr_db=None)
    (effect,) = [e for e in E.registered_effects() if e.name == "planet_position_errors"]
    twins = {"spec": build_twin(load_spec(d), kind="torsional"),
             "effect": base.with_parts(*effect.parts(jnp.asarray(err[1:]), base, kin)),
             "pins": base.with_parts(PlanetPositionErrors(jnp.asarray(err)))}
    level = {}
    for name, tw in twins.items():
        f, a = amplitude_spectrum(np.asarray(simulate(tw, duration=1.0, f_sun=kin.f_sun,
                                                      daq=daq).signal), daq.sample_rate, "hann")
        f, a = np.asarray(f), np.asarray(a)

        def db(fr, f=f, a=a):
            i = int(np.argmin(np.abs(f - fr)))
            return 20 * np.log10(a[i - 1:i + 2].max())

        level[name] = np.array([db(m * kin.f_mesh + n * kin.f_carrier) - db(kin.f_mesh)
                                for m in (1, 2, 3, 4) for n in (-2, -1, 1, 2)])
    assert np.all(level["spec"] < -8.0)  # the lines are there (the ideal twin's sit ≤ −70 dB)
    np.testing.assert_allclose(level["effect"], level["spec"], atol=0.3)
    assert np.max(np.abs(level["pins"] - level["spec"])) > 10.0


def test_planet_fault_candidate_has_a_severity_per_flank():
    """The planet fault candidate holds one pitting per flank of the planet tooth (the sun's and
    the ring's, each its own severity): with the ring flank's alone the sun meshes lose nothing
    and the ring mesh of planet 0 what a ring-flank Pitting of that severity removes; both
    together are the sum; the main value is the worse flank's; a fixed flank keeps one."""
    from dtwin.identify.discover.effects.local_fault import LocalFaultEffect
    from dtwin.model.faults import Pitting

    tw = build_twin(preset("paper-sim"), kind="torsional")
    kin = Kinematics.from_gear_set(tw.lp, 30.0)
    eff = LocalFaultEffect(location="planet")
    assert eff.name == "planet_local_fault" and eff.group == "planet_fault"
    assert [q.name for q in eff.parameters(tw)] == ["planet_fault_sun", "planet_fault_ring"]
    theta_p = jnp.array([0.21, 1.3, 2.5])

    def loss(parts):
        sp = sum(p.fault.stiffness_loss(tw.lp, 0.4, 0.1, 0.0, theta_p)[0] for p in parts)
        rp = sum(p.fault.stiffness_loss(tw.lp, 0.4, 0.1, 0.0, theta_p)[1] for p in parts)
        return np.asarray(sp), np.asarray(rp)

    ring = Pitting(0.3, location="planet", flank="ring").stiffness_loss(tw.lp, 0.4, 0.1, 0.0,
                                                                         theta_p)
    sun = Pitting(0.2, location="planet", flank="sun").stiffness_loss(tw.lp, 0.4, 0.1, 0.0,
                                                                       theta_p)
    assert np.asarray(ring[1]).any() and np.asarray(sun[0]).any()  # the tooth in contact
    sp, rp = loss(eff.parts(jnp.array([0.0, 0.3]), tw, kin))
    assert not sp.any()
    np.testing.assert_allclose(rp, ring[1], rtol=1e-12)
    sp, rp = loss(eff.parts(jnp.array([0.2, 0.3]), tw, kin))
    np.testing.assert_allclose(sp, sun[0], rtol=1e-12)
    np.testing.assert_allclose(rp, ring[1], rtol=1e-12)
    assert float(eff.main(jnp.array([0.2, 0.3]))) == pytest.approx(0.3)
    fixed = LocalFaultEffect(location="planet", flank="ring")
    assert fixed.name == "planet_local_fault_ring"
    assert [q.name for q in fixed.parameters(tw)] == ["planet_fault_ring"]
    assert len(fixed.parts(jnp.array([0.3]), tw, kin)) == 1
