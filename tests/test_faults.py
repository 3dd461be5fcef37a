"""Tests of dtwin.model.faults: exact healthy limit, monotonicity, gradients against finite
differences, contact windows against the mesh-phase definition and rigid kinematics."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dtwin.errors import SpecError
from dtwin.model.faults import (
    MissingTooth,
    Pitting,
    RootCrack,
    crack_loss_fraction,
    make_fault,
    mesh_phases,
    mesh_stiffnesses,
    parse_fault,
    planet_tooth_phases,
    total_stiffness_loss,
)
from dtwin.model.lumped import make_lumped, replace
from dtwin.model.stiffness import mesh_stiffness_waveform, single_pair_from_mean

F64 = jnp.float64
ZS, ZP, ZR, N = 21, 30, 81, 3  # the paper's simulation gearbox (docs/references.md §1)
EPS_SP, EPS_RP = 1.611, 1.936  # its contact ratios (involute geometry, standard 20° gears)


def _lp(n=N, psi=None, phase0_rp=0.78255):
    """Lumped parameters of the simulation gearbox (phase0_rp: ring-vs-sun mesh phase of the
    standard 21/30/81 set from its contact positions; values of the other fields do not matter
    here except the mean stiffnesses)."""
    psi = 2 * np.pi * np.arange(n) / n if psi is None else psi
    return make_lumped(
        z_sun=ZS, z_planet=ZP, z_ring=ZR, n_planets=n, planet_angles=psi,
        rb_sun=0.021 * math.cos(0.349), rb_planet=0.030 * math.cos(0.349),
        rb_ring=0.081 * math.cos(0.349), centre_distance=0.051, alpha_sp=math.radians(20),
        alpha_rp=math.radians(20), eps_sp=EPS_SP, eps_rp=EPS_RP, phase0_sp=0.0,
        phase0_rp=phase0_rp, m_sun=0.05, m_ring=1.0, m_carrier=1.0, m_planet=0.1, J_sun=1e-5,
        J_ring=1e-2, J_carrier=1e-2, J_planet=5e-5, k_sun_planet=3.3e8, k_ring_planet=3.9e8,
        k_bearing_sun=1e8, k_bearing_ring=1e8, k_bearing_carrier=1e8, k_bearing_planet=1e8,
        k_torsion_sun=0.0, k_torsion_ring=1e9, k_torsion_carrier=0.0, zeta_sun_planet=0.05,
        zeta_ring_planet=0.05, zeta_support=0.03,
    )


@pytest.fixture(scope="module")
def lp():
    return _lp()


def rigid(theta_c, n=N):
    """Rigid-body angles with the ring fixed (docs/conventions.md: delta = 0):
    theta_s = theta_c (1 + Zr/Zs); rb_s (theta_s - theta_c) + rb_p (theta_p - theta_c) = 0 with
    rb proportional to z gives theta_p = theta_c - (Zr/Zp) theta_c."""
    tc = jnp.asarray(theta_c, dtype=F64)
    ts = tc * (1 + ZR / ZS)
    tp = jnp.broadcast_to((tc - tc * ZR / ZP)[..., None], tc.shape + (n,))
    return ts, tc, jnp.zeros_like(tc), tp


def relative_sun_revolution(n_samples):
    """Carrier angles covering one revolution of the sun relative to the carrier."""
    return jnp.arange(n_samples, dtype=F64) / n_samples * 2 * np.pi * ZS / ZR


# compiled once per fault structure and record length (severity values are traced arrays, so
# a new severity reuses the compiled function)
@eqx.filter_jit
def _stiffness_jit(lp, faults, ts, tc, tr, tp):
    return jax.vmap(lambda a, b, c, d: mesh_stiffnesses(lp, a, b, c, d, faults))(ts, tc, tr, tp)


@eqx.filter_jit
def _loss_jit(lp, faults, ts, tc, tr, tp):
    return jax.vmap(lambda a, b, c, d: total_stiffness_loss(faults, lp, a, b, c, d))(
        ts, tc, tr, tp)


def stiffness_series(lp, faults, tc):
    return _stiffness_jit(lp, tuple(faults), *rigid(tc, lp.n_planets))


def loss_series(lp, faults, tc):
    return _loss_jit(lp, tuple(faults), *rigid(tc, lp.n_planets))


ALL_FAULTS = [
    ("sun", MissingTooth, {}),
    ("sun", Pitting, {}),
    ("sun", RootCrack, {}),
    ("ring", MissingTooth, {}),
    ("ring", RootCrack, {}),
    ("planet", MissingTooth, {"planet": 1}),
    ("planet", Pitting, {"planet": 2, "flank": "both"}),
    ("planet", RootCrack, {"planet": 0}),
]


# ---------------------------------------------------------------------------------------------
# Healthy limit, monotonicity, gradients
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("loc,cls,kw", ALL_FAULTS)
def test_severity_zero_is_bit_identical(lp, loc, cls, kw):
    tc = relative_sun_revolution(600)
    healthy = stiffness_series(lp, (), tc)
    faulty = stiffness_series(lp, (cls(0.0, location=loc, tooth=2, **kw),), tc)
    for h, f in zip(healthy, faulty, strict=True):
        assert np.array_equal(np.asarray(h), np.asarray(f))  # bit for bit, not allclose


def test_severity_zero_is_bit_identical_under_jit(lp):
    ts, tc, tr, tp = rigid(0.0123)

    @jax.jit
    def k(sev):
        faults = (MissingTooth(sev, location="sun", tooth=0),
                  Pitting(sev, location="planet", planet=1, tooth=3))
        return mesh_stiffnesses(lp, ts, tc, tr, tp, faults)

    healthy = jax.jit(lambda: mesh_stiffnesses(lp, ts, tc, tr, tp))()
    for h, f in zip(healthy, k(jnp.asarray(0.0, dtype=F64)), strict=True):
        assert np.array_equal(np.asarray(h), np.asarray(f))


@pytest.mark.parametrize("loc,cls,kw", ALL_FAULTS)
def test_loss_grows_monotonically_with_severity(lp, loc, cls, kw):
    tc = relative_sun_revolution(3000)
    sev = np.linspace(0.0, 1.0, 6)
    losses = [loss_series(lp, (cls(s, location=loc, tooth=2, **kw),), tc) for s in sev]
    totals = [float(jnp.sum(a) + jnp.sum(b)) for a, b in losses]
    assert totals[0] == 0.0
    assert all(t1 > t0 for t0, t1 in zip(totals[:-1], totals[1:], strict=True))
    for (a0, b0), (a1, b1) in zip(losses[:-1], losses[1:], strict=True):  # pointwise non-decreasing
        assert bool(jnp.all(a1 >= a0)) and bool(jnp.all(b1 >= b0))
    # and the stiffness never goes negative (a mesh cannot pull back)
    k_sp, k_rp = stiffness_series(lp, (cls(1.0, location=loc, tooth=2, **kw),), tc)
    assert float(jnp.min(k_sp)) >= 0.0 and float(jnp.min(k_rp)) >= 0.0


def _central(f, x, h):
    return (f(x + h) - f(x - h)) / (2 * h)


GRADIENT_FAULTS = [ALL_FAULTS[0], ALL_FAULTS[4], ALL_FAULTS[6]]  # each type and location once


@pytest.mark.parametrize("loc,cls,kw", GRADIENT_FAULTS)
def test_gradient_wrt_severity_matches_finite_differences(lp, loc, cls, kw):
    # a few instants inside the faulty tooth's contact (sun tooth 2 with planet 0 enters at
    # phase_sp = 2, i.e. theta_s - theta_c = 2*2pi/21): dense sampling around there
    tc = relative_sun_revolution(4000)[::9]

    def total(s):
        k_sp, k_rp = stiffness_series(lp, (cls(s, location=loc, tooth=2, **kw),), tc)
        return jnp.sum(k_sp) + jnp.sum(k_rp)

    g = float(jax.grad(total)(jnp.asarray(0.3, dtype=F64)))
    fd = _central(lambda s: float(total(jnp.asarray(s, dtype=F64))), 0.3, 1e-5)
    assert g < 0.0
    np.testing.assert_allclose(g, fd, rtol=1e-7)


@pytest.mark.parametrize("mesh", ["k_sun_planet", "k_ring_planet"])
def test_gradient_wrt_mean_stiffness_matches_finite_differences(lp, mesh):
    faults = (MissingTooth(0.6, location="sun", tooth=1),
              Pitting(0.4, location="planet", planet=0, flank="both"),
              RootCrack(0.5, location="ring", tooth=5))
    tc = relative_sun_revolution(4000)[::20]

    def total(k):
        k_sp, k_rp = stiffness_series(replace(lp, **{mesh: k}), faults, tc)
        return jnp.sum(k_sp * jnp.cos(3.0 * tc)[:, None]) + jnp.sum(k_rp * jnp.sin(5.0 * tc)[:, None])

    k0 = float(getattr(lp, mesh))
    g = float(jax.grad(total)(jnp.asarray(k0, dtype=F64)))
    fd = _central(lambda k: float(total(jnp.asarray(k, dtype=F64))), k0, 1e3)
    np.testing.assert_allclose(g, fd, rtol=1e-7)


# ---------------------------------------------------------------------------------------------
# Windows: where and how long
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("tooth", [0, 7])
def test_sun_window_duration_and_angle(lp, tooth):
    # sun tooth j meets planet i while (phase_sp_i - j) mod Zs in [0, eps): for eps/Zs of one
    # relative sun revolution, centred at theta_s - theta_c = psi_i + 2 pi (j + eps/2)/Zs
    n_s = 20000
    tc = relative_sun_revolution(n_s)
    dk_sp, dk_rp = loss_series(lp, (MissingTooth(1.0, location="sun", tooth=tooth),), tc)
    c1 = float(single_pair_from_mean(lp.k_sun_planet, lp.eps_sp))
    w = np.asarray(dk_sp) / c1  # (time, planet), the window itself for a missing tooth
    assert float(jnp.max(jnp.abs(dk_rp))) == 0.0
    np.testing.assert_allclose(w.mean(axis=0), EPS_SP / ZS, rtol=1e-3)
    rel = np.asarray(tc) * ZR / ZS  # theta_s - theta_c, 0..2pi
    for i in range(N):
        centre = np.angle(np.sum(w[:, i] * np.exp(1j * rel)))
        expected = 2 * np.pi * i / N + 2 * np.pi * (tooth + EPS_SP / 2) / ZS
        assert abs(np.angle(np.exp(1j * (centre - expected)))) < 1e-3
        assert w[:, i].max() == pytest.approx(1.0, abs=1e-6)


def _count_events(x, level):
    """Rising crossings of `level` in a periodic series."""
    above = x > level
    return int(np.sum(above & ~np.roll(above, 1)))


def test_sun_fault_hits_each_planet_once_per_relative_revolution(lp):
    tc = relative_sun_revolution(12000)
    dk_sp, _ = loss_series(lp, (MissingTooth(0.8, location="sun", tooth=4),), tc)
    dk = np.asarray(dk_sp)
    level = 0.5 * dk.max()
    assert _count_events(dk.sum(axis=1), level) == N
    assert [_count_events(dk[:, i], level) for i in range(N)] == [1] * N
    # in turn: planet 0, then 1, then 2 (the sun turns CCW relative to the carrier and the
    # planets are numbered CCW), one third of a relative revolution apart
    starts = [int(np.argmax(dk[:, i] > level)) for i in range(N)]
    assert starts[0] < starts[1] < starts[2]
    gaps = np.diff(starts) / len(tc)
    np.testing.assert_allclose(gaps, 1 / N, atol=2e-3)


def test_ring_fault_hits_each_planet_once_per_carrier_revolution(lp):
    # ring tooth j meets planet i while (phase_rp_i - j) mod Zr in [0, eps_rp): one carrier
    # revolution (ring fixed) brings every planet past it once
    tc = jnp.arange(30000, dtype=F64) / 30000 * 2 * np.pi
    dk_sp, dk_rp = loss_series(lp, (MissingTooth(1.0, location="ring", tooth=10),), tc)
    dk = np.asarray(dk_rp)
    assert float(jnp.max(jnp.abs(dk_sp))) == 0.0
    assert [_count_events(dk[:, i], 0.5 * dk.max()) for i in range(N)] == [1] * N
    c1 = float(single_pair_from_mean(lp.k_ring_planet, lp.eps_rp))
    np.testing.assert_allclose(dk.mean(axis=0) / c1, EPS_RP / ZR, rtol=1e-3)


def test_planet_fault_only_affects_its_planet_and_both_meshes(lp):
    # one revolution of the planet relative to the carrier: tooth k meets the sun once and the
    # ring once (a missing tooth affects both flanks)
    n_s = 20000
    tc = jnp.arange(n_s, dtype=F64) / n_s * 2 * np.pi * ZP / ZR
    dk_sp, dk_rp = loss_series(lp, (MissingTooth(1.0, location="planet", planet=1, tooth=5),), tc)
    dk_sp, dk_rp = np.asarray(dk_sp), np.asarray(dk_rp)
    for other in (0, 2):
        assert dk_sp[:, other].max() == 0.0 and dk_rp[:, other].max() == 0.0
    c_sp = float(single_pair_from_mean(lp.k_sun_planet, lp.eps_sp))
    c_rp = float(single_pair_from_mean(lp.k_ring_planet, lp.eps_rp))
    assert _count_events(dk_sp[:, 1], 0.5 * c_sp) == 1
    assert _count_events(dk_rp[:, 1], 0.5 * c_rp) == 1
    np.testing.assert_allclose(dk_sp[:, 1].mean() / c_sp, EPS_SP / ZP, rtol=1e-3)
    np.testing.assert_allclose(dk_rp[:, 1].mean() / c_rp, EPS_RP / ZP, rtol=1e-3)
    # "about half a planet turn later": the ring contact starts (Zp - 1)/2 + O(1) cycles after
    # the sun contact, i.e. near half of the Zp cycles of this record
    t_sun = int(np.argmax(dk_sp[:, 1] > 0.5 * c_sp))
    t_ring = int(np.argmax(dk_rp[:, 1] > 0.5 * c_rp))
    delay_cycles = ((t_ring - t_sun) % n_s) / n_s * ZP
    assert abs(delay_cycles - (ZP - 1) / 2) < 1.0


def test_pitting_defaults_to_the_sun_flank_and_sits_in_the_band(lp):
    n_s = 20000
    tc = jnp.arange(n_s, dtype=F64) / n_s * 2 * np.pi * ZP / ZR
    f = Pitting(0.5, location="planet", planet=0, tooth=3)
    dk_sp, dk_rp = loss_series(lp, (f,), tc)
    assert float(jnp.max(dk_rp)) == 0.0
    # loss integral = severity * c' * band_width * eps (in mesh cycles): closed form of the box
    c_sp = float(single_pair_from_mean(lp.k_sun_planet, lp.eps_sp))
    cycles = np.asarray(dk_sp[:, 0]).sum() / n_s * ZP
    np.testing.assert_allclose(cycles / c_sp, 0.5 * 0.4 * EPS_SP, rtol=2e-3)
    # the band is centred at band_centre * eps after the tooth enters sun contact
    q_sp, _ = jax.vmap(lambda a, b: planet_tooth_phases(lp, a, b))(*rigid(tc)[1::2])
    u = np.asarray(q_sp[:, 0]) - 3
    wts = np.asarray(dk_sp[:, 0])
    assert np.sum(wts * u) / np.sum(wts) == pytest.approx(0.5 * EPS_SP, abs=1e-3)


def test_planet_counters_follow_the_mesh_phases_under_rigid_kinematics(lp):
    # independent of the planet-spin formula: rigid kinematics make the planet-tooth counter of
    # the sun mesh equal to the sun-mesh phase and the ring counter differ from the ring-mesh
    # phase by an integer (so fault windows line up with the single/double contact zones)
    tc = jnp.asarray([0.0, 0.137, 1.9, -0.4], dtype=F64)
    for t in tc:
        ts, tc_, tr, tp = rigid(t)
        ph_sp, ph_rp = mesh_phases(lp, ts, tc_, tr)
        q_sp, q_rp = planet_tooth_phases(lp, tc_, tp)
        np.testing.assert_allclose(np.asarray(q_sp), np.asarray(ph_sp), atol=1e-12)
        d = np.asarray(ph_rp - q_rp)
        np.testing.assert_allclose(d, np.round(d), atol=1e-12)


def test_sun_to_ring_tooth_offset_matches_contact_geometry():
    # Independent contact-position calculation for the standard 21/30/81 set, module 2 mm,
    # 20 deg, a = 51 mm, planet at psi = 0 (carrier frame). Planet tooth k's trailing flank enters
    # the sun mesh at the planet tip (sun drives), its leading flank enters the ring mesh at the
    # ring tip (planet drives the ring). Measured along each line of action from the planet's
    # tangent point, in base pitches p_b = 2 pi rb_p / Zp:
    #   sun-mesh entry at  -sqrt(ra_p^2 - rb_p^2)            (planet tip, approaching T2)
    #   ring-mesh entry at a sin(alpha) - sqrt(ra_r^2 - rb_r^2) beyond T3 (ring tip)
    # and the planet turns by pi - 2 alpha - 2 psi_b between the two lines for the same flank
    # point (psi_b = half tooth angle at the base circle). The sum is the (unreduced) number of
    # cycles from the ring-mesh entry to the sun-mesh entry of the same tooth.
    m, a, alpha = 0.002, 0.051, math.radians(20.0)
    rb_p, rb_r = m * ZP / 2 * math.cos(alpha), m * ZR / 2 * math.cos(alpha)
    ra_p, ra_r = m * (ZP / 2 + 1), m * (ZR / 2 - 1)
    pb = 2 * math.pi * rb_p / ZP
    psi_b = math.pi / (2 * ZP) + (math.tan(alpha) - alpha)
    t_p, t_r = math.sqrt(ra_p**2 - rb_p**2), math.sqrt(ra_r**2 - rb_r**2)
    delta = (a * math.sin(alpha) - t_r - t_p + rb_p * (2 * alpha + 2 * psi_b - math.pi)) / pb
    # tooth k enters the ring mesh -delta cycles after entering the sun mesh; dtwin's counters
    # must give exactly that (fractional part from phase0_rp, integer part from the geometry)
    lp = _lp(phase0_rp=delta % 1.0)
    ts, tc, tr, tp = rigid(0.3)
    q_sp, q_rp = planet_tooth_phases(lp, tc, tp)
    np.testing.assert_allclose(np.asarray(q_rp - q_sp)[0], delta, atol=1e-9)
    assert 13.5 < -delta < 15.5  # about half a planet turn


# ---------------------------------------------------------------------------------------------
# Severity mapping, combination, errors
# ---------------------------------------------------------------------------------------------
def test_crack_loss_fraction_against_compliance_series():
    # independent form: the pair keeps 1/(1 + w_b((1-s)^-3 - 1) + w_s((1-s)^-1 - 1))
    s = np.linspace(0.0, 0.95, 20)
    wb, ws = 0.30, 0.09
    ref = 1.0 - 1.0 / (1.0 + wb * ((1 - s) ** -3 - 1) + ws * ((1 - s) ** -1 - 1))
    got = np.asarray(crack_loss_fraction(jnp.asarray(s, dtype=F64)))
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-15)
    assert float(crack_loss_fraction(0.0)) == 0.0  # exactly healthy
    assert float(crack_loss_fraction(1.0)) == pytest.approx(1.0, rel=1e-15)  # tooth gone
    assert np.all(np.diff(got) > 0)


def test_fully_missing_tooth_leaves_one_pair_less(lp):
    # closed form of the rectangular wave: a missing sun tooth in mesh with planet 0 removes one
    # pair: double contact 1.75 c' -> 0.75 c', single contact c' -> 0 (tooth 0 is in contact
    # for phase_sp in [0, eps): double [0, eps-1), single [eps-1, 1), double [1, eps))
    c1 = float(single_pair_from_mean(lp.k_sun_planet, lp.eps_sp))
    d = EPS_SP - 1
    phase = np.asarray([d / 2, (1 + d) / 2, 1 + d / 2])  # mid double, mid single, mid double
    tc = jnp.asarray(phase * 2 * np.pi / ZR, dtype=F64)  # planet 0: phase_sp = Zr theta_c / 2pi
    k_sp, _ = stiffness_series(lp, (MissingTooth(1.0, location="sun", tooth=0),), tc)
    np.testing.assert_allclose(np.asarray(k_sp[:, 0]) / c1, [0.75, 0.0, 0.75], atol=0.03)


def test_combined_faults_add(lp):
    tc = relative_sun_revolution(2000)
    f1 = MissingTooth(0.7, location="sun", tooth=3)
    f2 = Pitting(0.5, location="planet", planet=2, tooth=8, flank="both")
    a1, b1 = loss_series(lp, (f1,), tc)
    a2, b2 = loss_series(lp, (f2,), tc)
    a, b = loss_series(lp, (f1, f2), tc)
    np.testing.assert_allclose(np.asarray(a), np.asarray(a1 + a2), rtol=1e-15, atol=0)
    np.testing.assert_allclose(np.asarray(b), np.asarray(b1 + b2), rtol=1e-15, atol=0)
    # and the faulty stiffness is the healthy waveform minus the summed loss
    k_sp, k_rp = stiffness_series(lp, (f1, f2), tc)
    ph_sp, ph_rp = jax.vmap(lambda s, c, r: mesh_phases(lp, s, c, r))(*rigid(tc)[:3])
    healthy_sp = mesh_stiffness_waveform(ph_sp, lp.k_sun_planet, lp.eps_sp)
    np.testing.assert_allclose(np.asarray(k_sp), np.asarray(healthy_sp - a), rtol=1e-12)


def test_bad_faults_are_refused_with_the_field_named(lp):
    with pytest.raises(SpecError, match="severity"):
        MissingTooth(1.2)
    with pytest.raises(SpecError, match="location"):
        Pitting(0.3, location="carrier")
    with pytest.raises(SpecError, match="flank"):
        Pitting(0.3, location="planet", flank="left")
    ts, tc, tr, tp = rigid(0.1)
    with pytest.raises(SpecError, match="planet 3 does not exist"):
        MissingTooth(0.5, location="planet", planet=3).stiffness_loss(lp, ts, tc, tr, tp)
    with pytest.raises(SpecError, match="teeth 0..20"):
        MissingTooth(0.5, location="sun", tooth=21).stiffness_loss(lp, ts, tc, tr, tp)
    with pytest.raises(SpecError, match="kind"):
        make_fault("chipped", "sun", 0.2)
    with pytest.raises(SpecError, match="LOCATION:KIND:SEVERITY"):
        parse_fault("sun-missing")


def test_parse_fault():
    f = parse_fault("planet:pitting:0.25:4:1")
    assert isinstance(f, Pitting)
    assert (f.location, f.tooth, f.planet, f.flank) == ("planet", 4, 1, "sun")
    assert float(f.severity) == 0.25 and f.severity.dtype == jnp.float64
    g = parse_fault("sun:missing_tooth:0.5")
    assert isinstance(g, MissingTooth) and g.location == "sun" and g.flank == "both"
    assert isinstance(parse_fault("ring:crack:0.1:3"), RootCrack)


def test_faults_from_spec_tables_match_direct_construction(lp):
    from dtwin.model.faults import faults_from_table

    entries = [{"type": "missing_tooth", "location": "sun", "severity": 0.4, "tooth": 2},
               {"type": "crack", "location": "planet", "severity": 0.3, "tooth": 1, "planet": 2,
                "flank": "sun"}]
    got = faults_from_table(entries)
    direct = (MissingTooth(0.4, location="sun", tooth=2),
              RootCrack(0.3, location="planet", tooth=1, planet=2, flank="sun"))
    tc = relative_sun_revolution(500)
    for a, b in zip(loss_series(lp, got, tc), loss_series(lp, direct, tc), strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    with pytest.raises(SpecError, match=r"faults\[0\].severity"):
        faults_from_table([{"type": "pitting", "location": "sun"}])


# ------------------------------------------------------------------ peak mesh-stiffness loss
def test_peak_stiffness_loss_closed_forms(lp):
    """Sharp edges: a missing tooth of severity s removes s c' in single contact, where the
    healthy mesh has c' (peak s); a root crack g(s); pitting whose band covers the single-contact
    zone s. Against the stiffness the twin itself loses (mesh_stiffnesses), sampled densely."""
    from dtwin.model.faults import peak_stiffness_loss

    for s in (0.1, 0.5, 0.9):
        assert float(peak_stiffness_loss(MissingTooth(s), lp)) == pytest.approx(s, rel=1e-4)
        assert float(peak_stiffness_loss(RootCrack(s), lp)) == pytest.approx(
            float(crack_loss_fraction(s)), rel=1e-4)
        assert float(peak_stiffness_loss(Pitting(s), lp)) == pytest.approx(s, rel=2e-2)
    # ring faults use the ring mesh's contact ratio; a float is taken as the contact ratio
    assert float(peak_stiffness_loss(MissingTooth(0.4, location="ring"), lp)) == pytest.approx(
        0.4, rel=1e-4)
    assert float(peak_stiffness_loss(MissingTooth(0.4), EPS_SP)) == pytest.approx(0.4, rel=1e-4)
    # the twin's own loss: max of dk / k_ideal over a sun revolution equals the peak
    tc = relative_sun_revolution(20000)
    f = MissingTooth(0.5, location="sun")
    dk_sp, _ = loss_series(lp, (f,), tc)
    c1 = float(single_pair_from_mean(lp.k_sun_planet, lp.eps_sp))
    assert float(jnp.max(dk_sp)) / c1 == pytest.approx(0.5, rel=1e-3)


def test_ramp_spreads_the_loss_and_keeps_its_area(lp):
    """A wider ramp spreads the same loss over more of the passage: the area ∫ f w du is
    s·eps/(1 − exp(−eps/ramp)) (∫σ(x)σ(c − x)dx = c/(1 − e^(−c)), the sigmoid edges), ≈ s·eps;
    the peak drops below s, and severity 0 stays exactly 0."""
    from dtwin.model.faults import (
        peak_stiffness_loss,
        severity_for_peak_loss,
        stiffness_loss_profile,
    )

    u = jnp.linspace(-5.0, 7.0, 24001)
    du = float(u[1] - u[0])
    for ramp in (0.05, 0.15, 0.3):
        f = MissingTooth(0.5, ramp=ramp)
        healthy = jnp.where(jnp.mod(u, 1.0) < EPS_SP - 1.0, 1.75, 1.0)
        area = float(jnp.sum(stiffness_loss_profile(f, EPS_SP, u) * healthy)) * du
        assert area == pytest.approx(0.5 * EPS_SP / (1 - math.exp(-EPS_SP / ramp)), rel=1e-5)
    p_sharp = float(peak_stiffness_loss(MissingTooth(0.5), lp))
    p_wide = float(peak_stiffness_loss(MissingTooth(0.5, ramp=0.3), lp))
    assert p_wide < 0.95 * p_sharp
    # the inverse
    for ramp in (0.05, 0.3):
        f = MissingTooth(0.5, ramp=ramp)
        s = severity_for_peak_loss(f, lp, 0.36)
        g = eqx.tree_at(lambda x: x.severity, f, jnp.asarray(s))
        assert float(peak_stiffness_loss(g, lp)) == pytest.approx(0.36, rel=1e-6)
    # severity 0: the loss is exactly zero whatever the ramp
    tc = relative_sun_revolution(500)
    dk_sp, dk_rp = loss_series(lp, (MissingTooth(0.0, ramp=0.3),), tc)
    assert not np.any(np.asarray(dk_sp)) and not np.any(np.asarray(dk_rp))
    with pytest.raises(SpecError, match="ramp"):
        MissingTooth(0.5, ramp=0.0)


def test_peak_stiffness_loss_gradient_matches_finite_differences(lp):
    from dtwin.model.faults import peak_stiffness_loss

    def peak(r):
        return peak_stiffness_loss(RootCrack(0.4, ramp=r), lp)

    g = float(jax.grad(peak)(jnp.asarray(0.3)))
    h = 1e-5
    fd = (float(peak(0.3 + h)) - float(peak(0.3 - h))) / (2 * h)
    assert g == pytest.approx(fd, rel=1e-4, abs=1e-8)
