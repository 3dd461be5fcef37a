"""Tests of dtwin.model.gears: geometry, kinematics, mesh phasing and characteristic frequencies.

The mesh phases and contact ratios are checked against an independent contact calculation
written here: actual involute tooth flanks (polar tooth-thickness equation), placed in mesh
through the pitch points, turned kinematically; the contact point of a flank pair is found as the
point where the two flank curves touch, and a pair enters/leaves contact when that point reaches
a tip circle.
"""

from __future__ import annotations

import json
import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar

from dtwin.errors import GeometryError
from dtwin.model.gears import (
    GearSet,
    base_radii,
    characteristic_frequencies,
    contact_ratios,
    inverse_involute,
    involute,
    masses_and_inertias,
    mesh_phases,
    mesh_phasing,
    operating_pressure_angles,
    relative_mesh_phase,
    rigid_angles,
    tip_radii,
)

ALPHA = math.radians(20.0)
pytestmark = pytest.mark.filterwarnings("ignore:z_ring = 84")


def _sim(n: int = 3) -> GearSet:
    # paper Table 1: 21/30/81, m = 2 mm, 20°, 20 mm
    return GearSet(z_sun=21, z_planet=30, z_ring=81, n_planets=n, module=0.002,
                   face_width=0.02, pressure_angle=ALPHA)


def _bench() -> GearSet:
    # paper Table 3: 21/31/84 with a' = 52.5 mm (our documented choice)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return GearSet(z_sun=21, z_planet=31, z_ring=84, n_planets=3, module=0.002,
                       face_width=0.02, pressure_angle=ALPHA, centre_distance=0.0525)


def _odd4() -> GearSet:
    # a standard set with an odd planet and unequal per-planet phases: 21/31/83, N = 4
    # (Zs/N = 5.25, Zr/N = 20.75: sequentially phased planets)
    return GearSet(z_sun=21, z_planet=31, z_ring=83, n_planets=4, module=0.002,
                   face_width=0.02, pressure_angle=ALPHA)


PRESETS = {"sim": _sim, "bench": _bench, "odd4": _odd4}


# --- characteristic frequencies ------------------------------------------------------------------

@pytest.mark.parametrize(
    "make, f_sun, table",
    [
        # paper Table 2 (simulation, 1800 rpm): fm, fsr, fc, fs, fp
        (_sim, 30.0, dict(f_mesh=500.1, f_sun=30.0, f_carrier=6.2, f_sun_fault=71.4,
                          f_planet_fault=16.7)),
        # paper Table 4 (bench, 1782 rpm actual)
        (_bench, 29.7, dict(f_mesh=498.9, f_sun=29.7, f_carrier=5.9, f_sun_fault=71.3,
                            f_planet_fault=16.2)),
    ],
)
def test_frequencies_match_paper_tables(make, f_sun, table):
    f = characteristic_frequencies(make(), f_sun)
    for name, ref in table.items():
        assert f[name] == pytest.approx(ref, rel=0.01), name
    # the other conventions (docs/references.md §1): both flanks, ring fault, planet pass
    f2 = characteristic_frequencies(make(), f_sun, planet_fault="both_flanks")
    assert f2["f_planet_fault"] == pytest.approx(2 * f["f_planet_fault"])
    gs = make()
    assert f["f_ring_fault"] == pytest.approx(f["f_mesh"] * 3 / gs.z_ring)
    assert f["f_planet_pass"] == pytest.approx(3 * f["f_carrier"])
    # planet spin relative to the carrier from the rigid kinematics (independent route)
    ang = rigid_angles(gs, 2 * np.pi)  # one sun turn
    turns_rel = abs(float(ang["planet"] - ang["carrier"])) / (2 * np.pi)
    assert f["f_planet"] == pytest.approx(turns_rel * f_sun, rel=1e-12)


def test_frequency_arguments_checked():
    with pytest.raises(ValueError, match="planet_fault"):
        characteristic_frequencies(_sim(), 30.0, planet_fault="wrong")
    with pytest.raises(ValueError, match="f_sun"):
        characteristic_frequencies(_sim(), -1.0)


# --- geometry checks --------------------------------------------------------------------------

@pytest.mark.parametrize("n", [5, 6])
def test_paper_simulation_gearbox_refuses_5_or_6_planets(n):
    # 2 a sin(π/N) = 59.96 mm (N=5), 51 mm (N=6) < planet tip diameter 64 mm
    with pytest.raises(GeometryError, match="gears.n_planets") as e:
        _sim(n)
    assert e.value.problems[0][0] == "gears.n_planets"


def test_four_planets_fit_but_warn_on_unequal_spacing():
    # 2 a sin(π/4) = 72.1 mm > 64 mm fits; (21 + 81)/4 = 25.5 is not an integer
    with pytest.warns(UserWarning, match="not an integer"):
        gs = _sim(4)
    assert 2 * float(gs.centre_distance) * math.sin(math.pi / 4) > 2 * float(tip_radii(gs)[1])


@pytest.mark.parametrize(
    "kw, field",
    [
        (dict(z_sun=0), "gears.z_sun"),
        (dict(z_planet=-3), "gears.z_planet"),
        (dict(n_planets=0), "gears.n_planets"),
        (dict(module=-0.002), "gears.module"),
        (dict(pressure_angle=20.0), "gears.pressure_angle"),  # degrees: hint in the message
        (dict(planet_angles=[0.0, 1.0]), "gears.planet_angles"),
        (dict(x_ring=0.5), "gears.x_ring"),  # shifts that give two carrier radii
    ],
)
def test_impossible_geometry_names_the_field(kw, field):
    base = dict(z_sun=21, z_planet=30, z_ring=81, n_planets=3, module=0.002, face_width=0.02)
    base.update(kw)
    with pytest.raises(GeometryError) as e:
        GearSet(**base)
    assert field in [p for p, _ in e.value.problems]


def test_bench_warns_profile_shift_needed():
    with pytest.warns(UserWarning, match="profile shift") as record:
        gs = GearSet(z_sun=21, z_planet=31, z_ring=84, n_planets=3, module=0.002, face_width=0.02)
    assert any("profile shift" in str(w.message) for w in record)
    # the set is built (warned, not refused), with the shift that 84 != 21 + 2*31 needs
    assert abs(float(gs.x_sun)) + abs(float(gs.x_ring)) > 0.0


def test_default_centre_distance_and_shift_rule():
    gs = GearSet(z_sun=21, z_planet=31, z_ring=84, n_planets=3, module=0.002, face_width=0.02)
    # mean of the standard centre distances 52 and 53 mm
    assert float(gs.centre_distance) == pytest.approx(0.0525, abs=1e-12)
    assert float(gs.x_planet) == 0.0
    # shifts given explicitly reproduce the same set (one carrier radius)
    gs2 = GearSet(z_sun=21, z_planet=31, z_ring=84, n_planets=3, module=0.002, face_width=0.02,
                  x_sun=float(gs.x_sun), x_planet=0.0, x_ring=float(gs.x_ring))
    assert float(gs2.centre_distance) == pytest.approx(0.0525, abs=1e-9)


def test_inverse_involute():
    a = jnp.linspace(0.05, 1.2, 50, dtype=jnp.float64)
    np.testing.assert_allclose(inverse_involute(involute(a)), a, rtol=1e-13)


@pytest.mark.parametrize("name", ["sim", "bench"])
def test_zero_backlash_on_both_meshes(name):
    """Independent check of the shift rule: tooth thicknesses on the operating pitch circles.

    On the operating circles the tooth thickness of sun + planet equals the circular pitch, and
    the planet's tooth fills the ring's space (zero backlash, one carrier radius).
    """
    gs = PRESETS[name]()
    a, m = float(gs.centre_distance), 0.002
    zs, zp, zr = gs.z_sun, gs.z_planet, gs.z_ring
    rb = np.array([zs, zp, zr]) * m / 2 * math.cos(ALPHA)

    def half(z, x, rho, rbz):  # half tooth (or ring space) angle at radius rho
        w = m * (math.pi / 2 + 2 * x * math.tan(ALPHA))
        ar = math.acos(rbz / rho)
        return w / (m * z) + (math.tan(ALPHA) - ALPHA) - (math.tan(ar) - ar)

    rws, rwp = a * rb[0] / (rb[0] + rb[1]), a * rb[1] / (rb[0] + rb[1])
    xs, xp, xr = float(gs.x_sun), float(gs.x_planet), float(gs.x_ring)
    # angular thickness fractions of a pitch: sun + planet = 1
    frac = zs * half(zs, xs, rws, rb[0]) / math.pi + zp * half(zp, xp, rwp, rb[1]) / math.pi
    assert frac == pytest.approx(1.0, abs=1e-9)
    rwp2, rwr = a * rb[1] / (rb[2] - rb[1]), a * rb[2] / (rb[2] - rb[1])
    assert zp * half(zp, xp, rwp2, rb[1]) == pytest.approx(zr * half(zr, xr, rwr, rb[2]), abs=1e-9)
    # operating pressure angles: the lines of action are tangent to both base circles
    a_sp, a_rp = operating_pressure_angles(gs)
    assert a * math.cos(float(a_sp)) == pytest.approx(rb[0] + rb[1], rel=1e-12)
    assert a * math.cos(float(a_rp)) == pytest.approx(rb[2] - rb[1], rel=1e-12)


def test_masses_scale_like_geometry():
    gs = _sim()
    m1 = masses_and_inertias(gs)
    m2 = masses_and_inertias(gs, density=2 * 7850.0)
    for k in m1:
        assert float(m2[k]) == pytest.approx(2 * float(m1[k]), rel=1e-12)
    # similar discs: mass ~ r², inertia ~ r⁴ (sun 21 teeth vs planet 30 teeth)
    assert float(m1["m_planet"] / m1["m_sun"]) == pytest.approx((30 / 21) ** 2, rel=1e-12)
    assert float(m1["J_planet"] / m1["J_sun"]) == pytest.approx((30 / 21) ** 4, rel=1e-12)
    # a 21-tooth module-2 steel sun, 20 mm wide, is about 0.2 kg (disc of 42 mm diameter)
    assert 0.15 < float(m1["m_sun"]) < 0.3


def test_geometry_is_differentiable():
    gs = _sim()

    def eps_sp(module):
        return contact_ratios(eqx.tree_at(lambda g: g.module, gs, module))[0]

    m0 = jnp.asarray(0.002, dtype=jnp.float64)
    g = jax.grad(eps_sp)(m0)
    h = 1e-8
    fd = (eps_sp(m0 + h) - eps_sp(m0 - h)) / (2 * h)
    # reverse-mode derivative through the involute geometry against central differences
    assert float(g) == pytest.approx(float(fd), rel=1e-5)
    assert float(jax.jit(relative_mesh_phase)(gs)) == pytest.approx(float(relative_mesh_phase(gs)))


# --- rigid kinematics: no drift of the mesh deflections -------------------------------------------

@pytest.mark.parametrize("name", ["paper-sim", "paper-bench"])
def test_rigid_rotation_no_drift_with_preset_lumped_parameters(name):
    """The same with the base radii that lumped_from_spec hands to the dynamics."""
    from dtwin.spec import lumped_from_spec, preset

    lp = lumped_from_spec(preset(name))
    gs = preset(name).gear_set()
    ang = rigid_angles(gs, 2 * jnp.pi * 30.0 * jnp.linspace(0.0, 10.0, 2001, dtype=jnp.float64))
    ts, tc, tp = ang["sun"], ang["carrier"], ang["planet"]
    d_sp = lp.rb_sun * (ts - tc) + lp.rb_planet * (tp - tc)
    d_rp = lp.rb_ring * (0.0 - tc) - lp.rb_planet * (tp - tc)
    assert float(jnp.max(jnp.abs(d_sp))) < 1e-9 and float(jnp.max(jnp.abs(d_rp))) < 1e-9
    a = lp.centre_distance
    assert float(lp.rb_sun + lp.rb_planet) == pytest.approx(float(a * jnp.cos(lp.alpha_sp)))
    assert float(lp.rb_ring - lp.rb_planet) == pytest.approx(float(a * jnp.cos(lp.alpha_rp)))


@pytest.mark.parametrize("name", ["sim", "bench"])
def test_rigid_rotation_keeps_mesh_deflections_zero(name):
    """docs/conventions.md mesh deflections with rigid gears at constant speed, ring fixed."""
    gs = PRESETS[name]()
    t = jnp.linspace(0.0, 10.0, 20001, dtype=jnp.float64)
    ang = rigid_angles(gs, 2 * jnp.pi * 30.0 * t)  # 30 Hz for 10 s: 300 sun turns
    rb = base_radii(gs)
    a_sp, a_rp = operating_pressure_angles(gs)
    ts, tc, tp, tr = ang["sun"], ang["carrier"], ang["planet"], ang["ring"]
    # translations are zero in rigid motion; the projections n . (d_s - d_p) vanish
    d_sp = rb[0] * (ts - tc) + rb[1] * (tp - tc)
    d_rp = rb[2] * (tr - tc) - rb[1] * (tp - tc)
    assert float(jnp.max(jnp.abs(d_sp))) < 1e-9  # metres, after 300 turns
    assert float(jnp.max(jnp.abs(d_rp))) < 1e-9
    # ratio from the theory of the epicyclic train: θ_s = θ_c (1 + Zr/Zs)
    np.testing.assert_allclose(ts, tc * (1 + gs.z_ring / gs.z_sun), rtol=1e-13)
    # base-circle geometry used by both meshes is that of one carrier radius
    a = gs.centre_distance
    assert float(rb[0] + rb[1]) == pytest.approx(float(a * jnp.cos(a_sp)), rel=1e-13)
    assert float(rb[2] - rb[1]) == pytest.approx(float(a * jnp.cos(a_rp)), rel=1e-13)


# --- independent contact calculation --------------------------------------------------------------

class _Flanks:
    """Involute flanks of the actual teeth, placed in mesh, turned kinematically.

    Carrier frame. `u` = sun rotation relative to the carrier (rad); planet turns by
    −(Zs/Zp) u, ring by −(Zs/Zr) u (rigid kinematics of a fixed ring seen from the carrier).
    """

    def __init__(self, gs: GearSet):
        self.zs, self.zp, self.zr = gs.z_sun, gs.z_planet, gs.z_ring
        self.m, al = float(gs.module), float(gs.pressure_angle)
        self.al = al
        self.a = float(gs.centre_distance)
        self.x = (float(gs.x_sun), float(gs.x_planet), float(gs.x_ring))
        self.psi = np.asarray(gs.planet_angles)
        m = self.m
        self.rb = np.array([self.zs, self.zp, self.zr]) * m / 2 * math.cos(al)
        r = np.array([self.zs, self.zp, self.zr]) * m / 2
        self.ra = np.array([r[0] + m * (1 + self.x[0]), r[1] + m * (1 + self.x[1]),
                            r[2] - m * (1 - self.x[2])])
        rb = self.rb
        self.rws = self.a * rb[0] / (rb[0] + rb[1])
        self.rwp = self.a * rb[1] / (rb[0] + rb[1])
        self.rwp2 = self.a * rb[1] / (rb[2] - rb[1])
        self.rwr = self.a * rb[2] / (rb[2] - rb[1])
        # placement: a sun flank (CCW side of tooth 0) through the sun-mesh pitch point at u = 0
        self.phi_s = -self.half(0, self.rws)
        self.phi_p = []
        self.sun_pair = []  # (u at which sun tooth k and planet tooth 0 touch at the pitch point)
        pitch_u = 2 * math.pi / self.zs
        for psi in self.psi:
            u = float(np.mod(psi, pitch_u))
            k = round((psi - u) * self.zs / (2 * math.pi))
            # planet tooth 0, CCW-side flank, through the pitch point (direction psi + π)
            self.phi_p.append(psi + math.pi - self.half(1, self.rwp) + self.zs / self.zp * u)
            self.sun_pair.append((u, k))
        # ring placed against planet 0: a planet leading flank through the ring-mesh pitch point
        u1, j1 = self._planet_leading_at(0, 0.0)
        self.phi_r = self.half(2, self.rwr) + self.zs / self.zr * u1
        self.ring_pair = []
        for i, psi in enumerate(self.psi):
            ui, ji = self._planet_leading_at(i, psi)
            ang = self.ring_angle(ui) - self.half(2, self.rwr)
            k = round((psi - ang) * self.zr / (2 * math.pi))
            mis = (ang + 2 * math.pi * k / self.zr - psi + math.pi) % (2 * math.pi) - math.pi
            self.ring_pair.append((ui, ji, k, mis))

    def half(self, g: int, rho: float) -> float:
        """Half tooth angle (sun, planet) or half space angle (ring) at radius rho."""
        z = (self.zs, self.zp, self.zr)[g]
        w = self.m * (math.pi / 2 + 2 * self.x[g] * math.tan(self.al))
        ar = math.acos(min(1.0, self.rb[g] / rho))
        return w / (self.m * z) + (math.tan(self.al) - self.al) - (math.tan(ar) - ar)

    def sun_angle(self, u):
        return self.phi_s + u

    def planet_angle(self, i, u):
        return self.phi_p[i] - self.zs / self.zp * u

    def ring_angle(self, u):
        return self.phi_r - self.zs / self.zr * u

    def _planet_leading_at(self, i, psi):
        """First u >= 0 at which a planet-i CW-side flank passes its ring pitch point."""
        h = self.half(1, self.rwp2)
        per = 2 * math.pi / self.zs
        u = float(np.mod((self.phi_p[i] - h - psi) * self.zp / self.zs, per))
        j = round(((psi + h) - self.planet_angle(i, u)) * self.zp / (2 * math.pi))
        return u, j

    def centre(self, i):
        return self.a * np.array([math.cos(self.psi[i]), math.sin(self.psi[i])])

    @staticmethod
    def _wrap(x):
        return (x + math.pi) % (2 * math.pi) - math.pi

    def sun_contact(self, i, u):
        """Contact of the tracked sun-mesh pair: (radius on sun, radius on planet)."""
        _, k = self.sun_pair[i]
        c = self.centre(i)

        def g(rho):
            th = self.sun_angle(u) + 2 * math.pi * k / self.zs + self.half(0, rho)
            p = rho * np.array([math.cos(th), math.sin(th)]) - c
            R = math.hypot(*p)
            if R <= self.rb[1]:
                return 1.0
            beta = math.atan2(p[1], p[0])
            return abs(self._wrap(beta - self.planet_angle(i, u) - self.half(1, R)))

        rho = self._argmin(g, self.rb[0] * 1.0000001, self.rb[0] * 1.6)
        th = self.sun_angle(u) + 2 * math.pi * k / self.zs + self.half(0, rho)
        p = rho * np.array([math.cos(th), math.sin(th)]) - c
        return rho, math.hypot(*p), g(rho)

    def ring_contact(self, i, u):
        """Contact of the tracked ring-mesh pair: (radius on planet, radius on ring)."""
        _, j, k, _ = self.ring_pair[i]
        c = self.centre(i)

        def point(rho):
            th = self.planet_angle(i, u) + 2 * math.pi * j / self.zp - self.half(1, rho)
            return c + rho * np.array([math.cos(th), math.sin(th)])

        def g(rho):
            p = point(rho)
            R = math.hypot(*p)
            if R <= self.rb[2]:
                return 1.0
            beta = math.atan2(p[1], p[0])
            return abs(self._wrap(beta - self.ring_angle(u) - 2 * math.pi * k / self.zr
                                  + self.half(2, R)))

        rho = self._argmin(g, self.rb[1] * 1.0000001, self.rb[1] * 1.6)
        return rho, math.hypot(*point(rho)), g(rho)

    @staticmethod
    def _argmin(g, lo, hi):
        grid = np.linspace(lo, hi, 400)
        vals = np.array([g(x) for x in grid])
        i = int(np.argmin(vals))
        a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        res = minimize_scalar(g, bounds=(a, b), method="bounded", options=dict(xatol=1e-13))
        return float(res.x)

    def sun_events(self, i):
        """(u_enter, u_leave): contact reaches the planet tip / the sun tip."""
        u0, _ = self.sun_pair[i]
        a_sp = math.acos((self.rb[0] + self.rb[1]) / self.a)
        span_in = 0.95 * self.rb[0] * math.tan(a_sp) / self.rb[0]
        span_out = 0.95 * self.rb[1] * math.tan(a_sp) / self.rb[0]
        enter = brentq(lambda u: self.sun_contact(i, u)[1] - self.ra[1], u0 - span_in, u0,
                       xtol=1e-13)
        leave = brentq(lambda u: self.sun_contact(i, u)[0] - self.ra[0], u0, u0 + span_out,
                       xtol=1e-13)
        return enter, leave

    def ring_events(self, i):
        """(u_enter, u_leave): contact reaches the ring tip / the planet tip."""
        u1 = self.ring_pair[i][0]
        a_rp = math.acos((self.rb[2] - self.rb[1]) / self.a)
        span_in = 0.95 * self.rb[1] * math.tan(a_rp) / self.rb[0]
        span_out = 3 * math.pi * self.m * math.cos(self.al) / self.rb[0]
        enter = brentq(lambda u: self.ring_contact(i, u)[1] - self.ra[2], u1 - span_in, u1,
                       xtol=1e-13)
        leave = brentq(lambda u: self.ring_contact(i, u)[0] - self.ra[1], u1, u1 + span_out,
                       xtol=1e-13)
        return enter, leave


def _cdist(x: float) -> float:
    """Distance of x from the nearest integer (mesh cycles)."""
    return abs((x + 0.5) % 1.0 - 0.5)


@pytest.fixture(scope="module", params=["sim", "bench", "odd4"])
def contact(request):
    gs = PRESETS[request.param]()
    fl = _Flanks(gs)
    sun = [fl.sun_events(i) for i in range(gs.n_planets)]
    ring = [fl.ring_events(i) for i in range(gs.n_planets)]
    return gs, fl, sun, ring


def test_flanks_are_in_mesh_on_every_planet(contact):
    """The independent construction is consistent: each tracked pair touches (assembly)."""
    gs, fl, _, _ = contact
    for i in range(gs.n_planets):
        assert abs(fl.ring_pair[i][3]) < 1e-9  # ring flank through planet i's pitch point
        for u in np.linspace(-0.05, 0.05, 5):
            assert fl.sun_contact(i, fl.sun_pair[i][0] + u)[2] < 1e-9
            assert fl.ring_contact(i, fl.ring_pair[i][0] + u)[2] < 1e-9


def test_contact_ratios_agree_with_contact_tracking(contact):
    gs, _, sun, ring = contact
    eps_sp, eps_rp = contact_ratios(gs)
    for (e, lv), (re, rl) in zip(sun, ring, strict=True):
        assert gs.z_sun * (lv - e) / (2 * math.pi) == pytest.approx(float(eps_sp), abs=1e-6)
        assert gs.z_sun * (rl - re) / (2 * math.pi) == pytest.approx(float(eps_rp), abs=1e-6)


def test_mesh_phases_agree_with_contact_tracking(contact):
    """Phase 0 of every mesh of every planet falls where a new tooth pair enters contact."""
    gs, fl, sun, ring = contact
    zs = gs.z_sun
    # the convention's origin: planet 0's sun mesh enters at t = 0 (phase0_sp = 0)
    u_origin = sun[0][0]

    def angles(u):  # absolute angles for carrier-frame sun rotation u (ring fixed, θ_r = 0)
        tc = (u - u_origin) * zs / gs.z_ring
        return tc + (u - u_origin), tc

    ph = mesh_phasing(gs)
    assert float(ph.phase0_sp) == 0.0
    for i in range(gs.n_planets):
        ts, tc = angles(sun[i][0])
        p_sp, _ = mesh_phases(gs, ts, tc)
        assert _cdist(float(p_sp[i])) < 1e-6, (i, float(p_sp[i]))
        ts, tc = angles(ring[i][0])
        _, p_rp = mesh_phases(gs, ts, tc)
        assert _cdist(float(p_rp[i])) < 1e-6, (i, float(p_rp[i]))
    # and the relative phase of planet 0's two meshes directly
    delta_test = zs * (sun[0][0] - ring[0][0]) / (2 * math.pi)
    assert _cdist(delta_test - float(relative_mesh_phase(gs))) < 1e-6


def test_relative_phase_with_a_shifted_planet():
    """The simulation set at a' = 51.2 mm with a shifted planet (x_planet = 0.1, the sum and
    difference of the shift rule kept) through the same independent construction."""
    ref = GearSet(z_sun=21, z_planet=30, z_ring=81, n_planets=3, module=0.002, face_width=0.02,
                  centre_distance=0.0512)
    gs = GearSet(z_sun=21, z_planet=30, z_ring=81, n_planets=3, module=0.002, face_width=0.02,
                 x_sun=float(ref.x_sun) - 0.1, x_planet=0.1, x_ring=float(ref.x_ring) + 0.1)
    assert float(gs.centre_distance) == pytest.approx(0.0512, abs=1e-9)
    fl = _Flanks(gs)
    d = gs.z_sun * (fl.sun_events(0)[0] - fl.ring_events(0)[0]) / (2 * math.pi)
    assert _cdist(d - float(relative_mesh_phase(gs))) < 1e-6
    # the planet shift changes the relative phase (tooth thickness enters): not a constant
    assert _cdist(float(relative_mesh_phase(gs)) - float(relative_mesh_phase(ref))) > 1e-3


def test_per_planet_phases_are_sequential_for_the_odd_set():
    """Parker & Lin: with Zs/N = 5.25 the sun meshes of planets 0..3 are staggered by 1/4 cycle;
    (Zs + Zr)/N integer makes the ring meshes carry the same per-planet shift."""
    ph = mesh_phasing(_odd4())
    np.testing.assert_allclose(ph.gamma_sp, [0.0, 0.25, 0.5, 0.75], atol=1e-12)
    np.testing.assert_allclose(ph.gamma_rp, ph.gamma_sp, atol=1e-12)


# --- CLI: dtwin freqs -----------------------------------------------------------------------------

def test_cli_freqs_json_matches_paper_table(capsys):
    from dtwin.cli import main

    main(["freqs", "--preset", "paper-sim", "--json"])
    out = json.loads(capsys.readouterr().out)
    # paper Table 2 (docs/references.md §1)
    assert out["frequencies_hz"]["f_mesh"] == pytest.approx(500.1, rel=0.01)
    assert out["frequencies_hz"]["f_sun_fault"] == pytest.approx(71.4, rel=0.01)
    assert out["f_planet_fault_both_flanks_hz"] == pytest.approx(
        2 * out["frequencies_hz"]["f_planet_fault"])
    assert out["geometry"]["centre_distance"] == pytest.approx(0.051)


def test_cli_freqs_out_folder_and_f_sun_override(tmp_path, capsys):
    from dtwin.cli import main

    out_dir = tmp_path / "res"
    main(["freqs", "--preset", "paper-bench", "--f-sun", "29.7", "--out", str(out_dir)])
    table = capsys.readouterr().out
    assert "f_mesh" in table and "498.960" in table  # paper Table 4: 498.9 Hz
    res = json.loads((out_dir / "freqs.json").read_text())
    man = json.loads((out_dir / "manifest.json").read_text())
    assert "freqs.json" in man["files"] and man["spec"]["gears"]["z_ring"] == 84
    assert res["frequencies_hz"] == pytest.approx(characteristic_frequencies(_bench(), 29.7))
    # an existing result is not overwritten without --force
    with pytest.raises(SystemExit) as e:
        main(["freqs", "--preset", "paper-bench", "--out", str(out_dir)])
    assert e.value.code == 2
    main(["freqs", "--preset", "paper-bench", "--out", str(out_dir), "--force", "--json"])


def test_cli_freqs_spec_file_and_errors(tmp_path, capsys):
    from dtwin.cli import main

    spec = tmp_path / "box.toml"
    spec.write_text("[gears]\nz_sun = 21\nz_planet = 30\nz_ring = 81\nn_planets = 3\n"
                    "module = 0.002\nface_width = 0.02\n")
    with pytest.raises(SystemExit) as e:
        main(["freqs", "--spec", str(spec)])  # no operating.f_sun in the file
    assert e.value.code == 2
    assert "--f-sun" in capsys.readouterr().err
    main(["freqs", "--spec", str(spec), "--f-sun", "30", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert out["frequencies_hz"]["f_carrier"] == pytest.approx(30 * 21 / 102)
    with pytest.raises(SystemExit):
        main(["freqs", "--spec", str(spec), "--f-sun", "1800"])  # rpm slip
    assert "1800 rpm = 30 Hz" in capsys.readouterr().err
