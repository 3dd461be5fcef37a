"""The twin's assembled equations against an independent NumPy implementation.

`tests/reference_numpy.py` re-implements the equations of motion from docs/conventions.md
and the docstrings (mass matrix from the kinetic energy, deflection matrix written out by hand,
stiffness waveform, sun-fault window, one-sided contact, supports, rotating-frame forces, drive,
load, sensor); only the numbers come from the built twin. At random states near the operating
point — some meshes in the smoothed contact zone, the faulty tooth in contact with a planet —
`Twin.vector_field` must equal it to ~1e-9 relative, for both model kinds, healthy and with a
sun missing tooth at severity 0.5.
"""

from __future__ import annotations

import copy
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from reference_numpy import ReferenceModel  # the test oracle, a helper beside this file

from dtwin.model.faults import MissingTooth
from dtwin.simulation.simulate import _observe, initial_state, state_scales
from dtwin.spec import preset
from dtwin.spec.build import build_twin

KINDS = ("translational", "torsional")
FAULT_TOOTH = 3
N_STATES = 6
RTOL = 1e-9


@eqx.filter_jit
def _jax_rhs(twin, ts, z, zd, aux):
    """`Twin.vector_field` at a batch of states (unscaled) and the scaled flat form of `_solve`."""
    ops = twin.operators()
    sz, sv = state_scales(twin)

    def one(t, z1, zd1, a1):
        dz, dzd, daux = twin.vector_field(t, (z1, zd1, a1), ops)
        sensor = _observe(twin, ops, "acceleration", t, (z1, zd1, a1))["signal"]
        return dz, dzd, daux, jnp.concatenate([dz / sz, dzd / sv, daux]), sensor

    return jax.vmap(one)(ts, z, zd, aux)


@pytest.fixture(scope="module")
def spec():
    return preset("paper-sim")


def _twin(spec, kind, severity):
    faults = () if severity is None else (MissingTooth(severity, location="sun", tooth=FAULT_TOOTH),)
    return build_twin(spec, kind=kind, faults=faults)


def _states(twin, ref: ReferenceModel, seed: int):
    """Random states near rigid rotation at the operating speed.

    States 0-3: the static deflections under the load (`initial_state`, meshes pressed by
    ~1e-6 m) plus noise; states 4-5: deflections of a few contact-smoothing lengths around zero
    (both sides of the one-sided contact). The carrier angle puts sun tooth `FAULT_TOOTH` inside
    its contact interval with a planet (mid-contact or near an edge of the window); rates, the
    drive's rotor angle and time random.
    """
    rng = np.random.default_rng(seed)
    n = ref.n_dof
    eps = ref.eps_sp
    z_static = np.asarray(initial_state(twin, 30.0)[0])
    out = []
    for j in range(N_STATES):
        # planet j % N meets the faulty tooth u cycles after its entry (rigid kinematics:
        # phase_sp_i = Zr theta_c / 2 pi - Zs psi_i / 2 pi)
        i = j % ref.n
        u = [0.5 * eps, 0.12, eps - 0.12, 0.3 * eps, 0.8 * eps, 0.5 * eps][j]
        cycles = FAULT_TOOTH + u + ref.zs * (rng.integers(0, 40) + ref.psi[i] / (2 * math.pi))
        theta_c = 2 * math.pi * cycles / ref.zr
        if j < 4:
            z = z_static + rng.normal(size=n) * ref.sz * 0.03
        else:
            z = rng.normal(size=n) * ref.sz * 0.05  # ~5e-8 m: 2.5 smoothing lengths
        zd = rng.normal(size=n) * ref.sv * 0.3
        z[ref.i_tc] = theta_c
        zd[ref.i_tc] = 2 * math.pi * 30.0 / (1 + ref.zr / ref.zs) * (1 + 0.01 * rng.normal())
        aux = rng.uniform(-1.0, 1.0, size=ref.n_aux) * 1e-3 + theta_c * (1 + ref.zr / ref.zs)
        out.append((rng.uniform(0.0, 4.0), z, zd, aux))
    return out


@pytest.fixture(scope="module", params=[(k, s) for k in KINDS for s in (None, 0.5)],
                ids=lambda p: f"{p[0]}-{'healthy' if p[1] is None else 'sun_fault_0.5'}")
def case(request, spec):
    kind, severity = request.param
    twin = _twin(spec, kind, severity)
    ref = ReferenceModel(twin)
    states = _states(twin, ref, seed=7)
    ts = jnp.asarray([s[0] for s in states])
    z, zd, aux = (jnp.asarray(np.stack([s[k] for s in states])) for k in (1, 2, 3))
    got = [np.asarray(a) for a in _jax_rhs(twin, ts, z, zd, aux)]
    return kind, severity, twin, ref, states, got, twin.operators()


def _close(a, b, what, atol=0.0):
    """|a - b| <= RTOL |b| + atol, element by element (atol may be an array)."""
    a, b = np.asarray(a), np.asarray(b)
    excess = np.abs(a - b) - (RTOL * np.abs(b) + atol)
    bad = np.flatnonzero(excess > 0)
    assert bad.size == 0, (f"{what}: entries {bad.tolist()} differ: jax {a[bad]}, numpy {b[bad]}, "
                           f"allowed {(RTOL * np.abs(b) + atol)[bad] if np.ndim(atol) else atol}")


def _rounding_floor(ref: ReferenceModel, z):
    """Absolute error of z'' that floating point alone allows (m/s², rad/s²).

    A deflection is the small difference of large rotation terms (``rb_s theta_s`` is metres
    after a few hundred radians; the deflection micrometres): its rounding error is about
    ``u sum_j |L_ij q_j|`` (u = 2.2e-16), ~1e-16 m at the angles of a 4 s run, and it reaches
    z'' as ``|P| |L|^T k_max delta_err``. Four times that estimate is still far below any
    physical slip (a sign or a factor changes z'' by ~1e-3 relative or more, see
    `test_states_exercise_contact_and_fault`).
    """
    q = ref.A @ z
    d_err = np.finfo(float).eps * (np.abs(ref.L) @ np.abs(q))
    k_max = np.max(ref.k_mean) * 1.75
    return 4.0 * np.abs(ref.P) @ (np.abs(ref.L).T @ (k_max * d_err))


def _aux_rounding_floor(ref: ReferenceModel, z):
    """The same rounding reaches the transfer path's filter (aux') through the ring-mesh forces:
    ``wc^2 sum_i F_err_i / m_ring``; zero for the drive's rotor angle."""
    q = ref.A @ z
    d_err = np.finfo(float).eps * (np.abs(ref.L) @ np.abs(q))
    k_max = np.max(ref.k_mean) * 1.75
    floor = np.zeros(ref.n_aux)
    wc = 2.0 * np.pi * ref.highpass_hz
    floor[ref.i_path + 1] = 4.0 * wc**2 * np.sum(k_max * d_err[ref.n:]) / ref.m_ring
    return floor


def test_operators_match(case):
    """Mass matrix, deflection matrix, supports and state scales, entry by entry."""
    _, _, twin, ref, _, _, ops = case
    np.testing.assert_allclose(np.asarray(twin.mass_matrix()), ref.M, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.asarray(ops.L), ref.L, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.asarray(ops.K), ref.K, rtol=1e-12, atol=1e-6)
    np.testing.assert_allclose(np.asarray(ops.C), ref.C, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(ops.A), ref.A, rtol=0, atol=0)
    sz, sv = state_scales(twin)
    np.testing.assert_allclose(np.asarray(sz), ref.sz, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(sv), ref.sv, rtol=1e-15)


def test_vector_field_matches_numpy(case):
    """`Twin.vector_field` = the NumPy right-hand side, unscaled and in `_solve`'s scaled form."""
    kind, severity, _, ref, states, (dz, dzd, daux, flat, _), _ = case

    def what(j):
        return f"{kind} {severity} state {j}: |z''| relative difference"

    for j, (t, z, zd, aux) in enumerate(states):
        rz, rzd, raux = ref.rhs_unscaled(t, z, zd, aux)
        floor = _rounding_floor(ref, z)
        assert np.all(floor < 1e-6 * np.max(np.abs(rzd))), "rounding floor should be tiny"
        _close(dz[j], rz, f"{kind} {severity} state {j}: z'")
        _close(dzd[j], rzd, f"{kind} {severity} state {j}: z''", atol=floor)
        aux_floor = _aux_rounding_floor(ref, z)
        _close(daux[j], raux, f"{kind} {severity} state {j}: aux'", atol=aux_floor)
        flat_atol = np.concatenate([np.zeros(ref.n_dof), floor / ref.sv, aux_floor])
        _close(flat[j], ref.rhs(t, ref.scale(z, zd, aux)), f"{kind} {severity} state {j}: scaled",
               atol=flat_atol)
        # and in the norm: ~1e-9 relative (observed 1e-14 at small angles, ~1e-9 at the
        # hundreds of radians of the loaded states, from the rounding described above)
        assert np.linalg.norm(dzd[j] - rzd) <= 10 * RTOL * np.linalg.norm(rzd), what(j)


def test_sensor_matches_numpy(case):
    """The sensor acceleration (ring motion in the fixed frame + high-passed windowed ring-mesh
    forces) of `dtwin.simulation.simulate._observe` equals the NumPy model's."""
    kind, severity, _, ref, states, (*_, sensor), _ = case
    for j, (t, z, zd, aux) in enumerate(states):
        want = ref.sensor_acceleration(t, ref.scale(z, zd, aux))
        # rounding floor: the ring-mesh force error over the ring mass, and the ring's z''
        q = ref.A @ z
        d_err = np.finfo(float).eps * (np.abs(ref.L) @ np.abs(q))
        floor = (4.0 * np.sum(np.max(ref.k_mean) * 1.75 * d_err[ref.n:]) / ref.m_ring
                 + np.max(_rounding_floor(ref, z)))
        assert abs(sensor[j] - want) <= RTOL * abs(want) + floor, (kind, severity, j, sensor[j], want)


def test_states_exercise_contact_and_fault(case):
    """The random states are not vacuous: meshes sit inside the smoothed contact zone, and the
    fault changes the accelerations far beyond the tolerance."""
    kind, severity, _, ref, states, _, _ = case
    x = np.stack([(ref.Lz @ s[1]) / ref.smoothing for s in states])
    assert np.all(x[:4] > 10.0), "the loaded states should press every mesh"
    assert np.mean(np.abs(x[4:]) < 3.0) > 0.3, "too few meshes in the smoothed contact zone"
    assert np.any(x[4:] < -3.0), "the unloaded states should include open meshes"
    if severity is None:
        return
    ref_h = copy.copy(ref)
    ref_h.sun_faults = []
    change = []
    for t, z, zd, aux in states:
        a = ref.rhs_unscaled(t, z, zd, aux)[1]
        b = ref_h.rhs_unscaled(t, z, zd, aux)[1]
        change.append(np.max(np.abs(a - b)) / np.max(np.abs(b)))
    assert min(change[:4]) > 1e6 * RTOL, f"the fault barely changes z'': {change}"


def test_rigid_rotation_is_undeflected(case):
    """Physics check of both sides: a rigid rotation of the whole gear set (every body turning by
    the kinematic ratios, no translation) leaves every mesh undeflected (docs/conventions.md)."""
    _, _, _, ref, _, _, ops = case
    z = np.zeros(ref.n_dof)
    z[ref.i_tc] = 0.37
    # zero up to the rounding of rb * theta (~1e-2 m): 1e-15 m
    np.testing.assert_allclose(ref.Lz @ z, 0.0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(ops.L) @ (ref.A @ z), 0.0, atol=1e-15)


def _moments(ref: ReferenceModel, L):
    """For each mesh: (moment about the gear centre of the translational mesh force applied at the
    pitch point, the rotational generalised force) for sun/ring and planet, per unit contact force.

    The mesh force is a pair of equal and opposite forces along the line of action, which passes
    through the operating pitch point ``P = (rb / cos alpha) e_r(psi_i)`` of each gear. Virtual
    work gives the force on a body as ``-dDelta/d(translation)`` and its torque as
    ``-dDelta/d(rotation)``; the torque must equal the moment ``(P - centre) x force``.
    """
    out = []
    psi = ref.psi
    for i in range(ref.n):
        er = np.array([math.cos(psi[i]), math.sin(psi[i])])
        et = np.array([-math.sin(psi[i]), math.cos(psi[i])])
        pin = ref.centre_distance * er
        for row, i_xy, rb, alpha in ((i, ref.i_sxy, ref.rb_sun, ref.alpha_sp),
                                     (ref.n + i, ref.i_rxy, ref.rb_ring, ref.alpha_rp)):
            i_t = ref.i_ts if row < ref.n else ref.i_tr
            p = rb / math.cos(alpha) * er
            f_body = -L[row, i_xy]
            f_planet = -(L[row, ref.i_zeta[i]] * er + L[row, ref.i_eta[i]] * et)
            out.append((p[0] * f_body[1] - p[1] * f_body[0], -L[row, i_t]))
            r = p - pin
            out.append((r[0] * f_planet[1] - r[1] * f_planet[0], -L[row, ref.i_tp[i]]))
            np.testing.assert_allclose(f_body + f_planet, 0.0, atol=1e-15)  # action = reaction
    return np.array(out)


def test_mesh_force_moments_match_torques(case):
    """Physics check of the deflection signs (translational model): the mesh force applied on the
    line of action has, about each gear's centre, the moment that the rotational part of the
    deflection gives as torque. (A sign slip in the translational part of one mesh — e.g. the
    ring's — flips the moment and fails here, while the rigid-rotation check still passes.)"""
    kind, _, _, ref, _, _, ops = case
    if kind != "translational":
        pytest.skip("the torsional model has no translations")
    for L in (ref.L, np.asarray(ops.L)):
        m = _moments(ref, L)
        np.testing.assert_allclose(m[:, 0], m[:, 1], rtol=1e-12, atol=1e-15)
