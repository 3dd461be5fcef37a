"""Tests of dtwin.model.modal against Lin & Parker (1999), closed forms and independent computations."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from dtwin.errors import OutputExistsError, ParameterError, SpecError
from dtwin.model.lumped import make_lumped, replace
from dtwin.model.modal import (
    coordinate_names,
    frequency_sensitivities,
    frequency_sensitivity,
    lin_parker_example,
    lin_parker_transform,
    mass_matrix,
    modal_analysis,
    natural_frequencies,
    stiffness_matrix,
)

# Lin & Parker (1999), J. Vib. Acoust. 121:316, Table 2 (docs/references.md §3), N = 3, in Hz.
LP_ROTATIONAL = [0.0, 1475.7, 1930.3, 2658.3, 7462.8, 11775.3]
LP_TRANSLATIONAL = [743.2, 1102.4, 1896.0, 2276.4, 6986.3, 9647.9]
LP_ALPHA = math.radians(24.6)


@pytest.fixture(scope="module")
def lp3():
    return lin_parker_example(3)


@pytest.fixture(scope="module")
def result3(lp3):
    return modal_analysis(lp3)


def _paper_sim_like(n_planets: int = 3):
    """A kinematically consistent module-2 set (Zs 21, Zp 30, Zr 81, 20 deg, standard gears).

    Base radii rb = m z cos(alpha) / 2 and centre distance a = m (Zs + Zp) / 2, so that
    rb_s + rb_p = a cos(alpha) and rb_r - rb_p = a cos(alpha) hold exactly. Masses of steel
    discs of 20 mm face (rho = 7850 kg/m^3); the values only need to be plausible.
    """
    m, alpha, b, rho = 2e-3, math.radians(20.0), 0.02, 7850.0
    zs, zp, zr = 21, 30, 81
    r_s, r_p = m * zs / 2, m * zp / 2
    disc = lambda r: (rho * math.pi * r**2 * b, 0.5 * rho * math.pi * r**2 * b * r**2)
    ms, js = disc(r_s)
    mp, jp = disc(r_p)
    return make_lumped(
        z_sun=zs, z_planet=zp, z_ring=zr, n_planets=n_planets,
        planet_angles=2 * np.pi * np.arange(n_planets) / n_planets,
        rb_sun=r_s * math.cos(alpha), rb_planet=r_p * math.cos(alpha),
        rb_ring=m * zr / 2 * math.cos(alpha), centre_distance=m * (zs + zp) / 2,
        alpha_sp=alpha, alpha_rp=alpha, eps_sp=1.6, eps_rp=1.8, phase0_sp=0.0, phase0_rp=0.0,
        m_sun=ms, m_ring=3.0, m_carrier=2.0, m_planet=mp,
        J_sun=js, J_ring=0.02, J_carrier=0.01, J_planet=jp,
        k_sun_planet=3e8, k_ring_planet=4e8,
        k_bearing_sun=1e8, k_bearing_ring=5e8, k_bearing_carrier=1e8, k_bearing_planet=2e8,
        k_torsion_sun=0.0, k_torsion_ring=1e7, k_torsion_carrier=0.0,
        zeta_sun_planet=0.05, zeta_ring_planet=0.05, zeta_support=0.03,
    )


# --- Lin & Parker's N = 3 example ---------------------------------------------------------------

def test_lin_parker_n3_frequencies_within_half_percent(result3):
    # Lin & Parker (1999) Table 2: every rotational frequency once, every translational twice.
    groups = result3.groups()
    rot = [g["frequency"] for g in groups if g["type"] == "rotational"]
    trans = [g["frequency"] for g in groups if g["type"] == "translational"]
    assert [g["multiplicity"] for g in groups if g["type"] == "rotational"] == [1] * 6
    assert [g["multiplicity"] for g in groups if g["type"] == "translational"] == [2] * 6
    assert not [g for g in groups if g["type"] in ("planet", "mixed")]
    assert rot[0] < 1e-3  # rigid-body mode (sun and carrier free to turn)
    np.testing.assert_allclose(rot[1:], LP_ROTATIONAL[1:], rtol=5e-3)
    np.testing.assert_allclose(trans, LP_TRANSLATIONAL, rtol=5e-3)


def test_solver_matches_scipy_generalised_eigh(lp3, result3):
    # Independent solver (LAPACK generalised problem) and the mass normalisation of the modes.
    m = np.asarray(mass_matrix(lp3))
    k = np.asarray(stiffness_matrix(lp3))
    lam = scipy.linalg.eigh(k, m, eigvals_only=True)
    f_ref = np.sqrt(np.clip(lam, 0.0, None)) / (2 * np.pi)
    np.testing.assert_allclose(np.asarray(result3.frequencies), f_ref, rtol=1e-9, atol=1e-3)
    phi = np.asarray(result3.mode_shapes)
    np.testing.assert_allclose(phi.T @ m @ phi, np.eye(18), atol=1e-10)
    omega2 = (2 * np.pi * np.asarray(result3.frequencies)) ** 2
    np.testing.assert_allclose(phi.T @ k @ phi, np.diag(omega2), atol=1e-6 * omega2.max())


def test_ring_mesh_line_of_action_sign_matters(lp3):
    # Flipping the sign of the translational part of the ring-mesh deflection (the planet pushes
    # the ring along n_rp, so delta_rp = n_rp.(d_p - d_r) + rb_r theta_r - rb_p theta_p; the
    # opposite sign pairs it with the wrong flank) changes the spectrum far beyond 0.5 %:
    # Lin & Parker's numbers pin the sign down.
    psi = np.asarray(lp3.planet_angles)
    a = LP_ALPHA
    g_wrong = np.zeros((3, 18))
    g_wrong[:, 3] = np.sin(psi + a)  # -e_t(psi + a) . d_r
    g_wrong[:, 4] = -np.cos(psi + a)
    g_wrong[:, 5] = 1.0
    g_right = g_wrong.copy()
    g_right[:, 3:5] *= -1.0
    for i in range(3):
        g_wrong[i, 9 + 3 * i: 12 + 3 * i] = [-np.sin(a), np.cos(a), -1.0]
        g_right[i, 9 + 3 * i: 12 + 3 * i] = [np.sin(a), -np.cos(a), -1.0]
    k = np.asarray(stiffness_matrix(lp3))
    # stiffness_matrix's ring-mesh part equals the hand-built "right" one ...
    k_no_ring = np.asarray(stiffness_matrix(lp3, k_ring_planet=0.0))
    np.testing.assert_allclose(k - k_no_ring, 5e8 * g_right.T @ g_right, atol=1e-3)
    # ... and the other sign moves the lowest translational mode from 743.2 Hz by > 10 %.
    lam = scipy.linalg.eigh(k_no_ring + 5e8 * g_wrong.T @ g_wrong, np.asarray(mass_matrix(lp3)),
                            eigvals_only=True)
    f_wrong = np.sqrt(np.clip(lam, 0, None)) / (2 * np.pi)
    assert abs(f_wrong[1] - 743.2) / 743.2 > 0.1


# --- N = 4, 5: multiplicities and the three mode types ----------------------------------------

@pytest.mark.parametrize("n", [4, 5])
def test_mode_type_multiplicities(n):
    # Lin & Parker (1999): 6 rotational modes (multiplicity 1), 6 translational pairs, and
    # 3 planet-mode frequencies of multiplicity N - 3; 3(N + 3) modes in all.
    lp = lin_parker_example(n)
    res = modal_analysis(lp)
    groups = res.groups()
    by_type = {t: [g["multiplicity"] for g in groups if g["type"] == t] for t in
               ("rotational", "translational", "planet", "mixed")}
    assert by_type == {"rotational": [1] * 6, "translational": [2] * 6, "planet": [n - 3] * 3,
                       "mixed": []}
    phi = np.asarray(res.mode_shapes)
    names = coordinate_names(n)
    xy = [j for j, s in enumerate(names) if s[:2] in ("x_", "y_")]
    u = [names.index(s) for s in ("u_s", "u_r", "u_c")]
    scale = np.abs(phi).max(axis=0)
    for j, t in enumerate(res.mode_types):
        central_t = np.abs(phi[xy, j]).max() / scale[j]
        central_r = np.abs(phi[u, j]).max() / scale[j]
        if t == "rotational":
            assert central_t < 1e-6
        elif t == "translational":
            assert central_r < 1e-6
        else:
            assert max(central_t, central_r) < 1e-6


@pytest.mark.parametrize("n", [4, 5])
def test_planet_modes_are_single_planet_with_central_members_clamped(n):
    # Lin & Parker: in a planet mode the central members are still, so its frequencies are those
    # of one planet (zeta, eta, u) on its bearing and the two mesh springs, written here by hand.
    s, c = math.sin(LP_ALPHA), math.cos(LP_ALPHA)
    g_s = np.array([-s, -c, 1.0])   # sun mesh deflection per (zeta, eta, u)
    g_r = np.array([s, -c, -1.0])   # ring mesh
    k = 5e8 * np.outer(g_s, g_s) + 5e8 * np.outer(g_r, g_r) + np.diag([1e8, 1e8, 0.0])
    m = np.diag([0.66, 0.66, 0.61])
    f_ref = np.sqrt(scipy.linalg.eigh(k, m, eigvals_only=True)) / (2 * np.pi)
    res = modal_analysis(lin_parker_example(n))
    planet = sorted(g["frequency"] for g in res.groups() if g["type"] == "planet")
    np.testing.assert_allclose(planet, f_ref, rtol=1e-9)


# --- planet torsional spring --------------------------------------------------------------------

def test_planet_torsional_spring_removes_rigid_body_mode(lp3, result3):
    # docs/references.md §3: a planet torsional spring (1e8 N/m on u) wrongly attached moves the
    # 0 Hz mode to about 556 Hz.
    assert float(result3.frequencies[0]) < 1e-3
    assert result3.mode_types[0] == "rotational"
    res = modal_analysis(lp3, k_torsion_planet=1e8)  # r_p = 1 m: 1e8 N*m/rad = 1e8 N/m on u
    f0 = float(res.frequencies[0])
    assert f0 > 100.0
    assert abs(f0 - 556.0) / 556.0 < 5e-3
    assert res.mode_types[0] == "rotational"


# --- torsional reduction --------------------------------------------------------------------

@pytest.mark.parametrize("n", [3, 4])
def test_torsional_reduction_against_hand_built_matrices(n):
    lp = _paper_sim_like(n)
    a, rs, rp, rr = (float(lp.centre_distance), float(lp.rb_sun), float(lp.rb_planet),
                     float(lp.rb_ring))
    cs, cr = math.cos(float(lp.alpha_sp)), math.cos(float(lp.alpha_rp))
    ksp, krp = float(lp.k_sun_planet), float(lp.k_ring_planet)
    # Rotations theta (rad): theta_s, theta_r, theta_c, theta_p_i. Rigid planet pins:
    # delta_sp = rb_s th_s + rb_p th_p - a cos(a_sp) th_c, delta_rp = rb_r th_r - rb_p th_p - a cos(a_rp) th_c
    d = n + 3
    k = np.zeros((d, d))
    for i in range(n):
        gs = np.zeros(d)
        gs[[0, 2, 3 + i]] = [rs, -a * cs, rp]
        gr = np.zeros(d)
        gr[[1, 2, 3 + i]] = [rr, -a * cr, -rp]
        k += ksp * np.outer(gs, gs) + krp * np.outer(gr, gr)
    k[1, 1] += float(lp.k_torsion_ring)
    m = np.diag([float(lp.J_sun), float(lp.J_ring),
                 float(lp.J_carrier) + n * float(lp.m_planet) * a**2] + [float(lp.J_planet)] * n)
    f_ref = np.sqrt(np.clip(scipy.linalg.eigh(k, m, eigvals_only=True), 0, None)) / (2 * np.pi)
    res = modal_analysis(lp, "torsional")
    np.testing.assert_allclose(np.asarray(res.frequencies), f_ref, rtol=1e-8, atol=1e-3)
    # Closed form of the planet modes (central members still): omega^2 = (k_sp + k_rp) rb_p^2 / J_p,
    # multiplicity N - 1; the other four modes are rotational.
    f_planet = math.sqrt((ksp + krp) * rp**2 / float(lp.J_planet)) / (2 * np.pi)
    groups = res.groups()
    assert [(g["type"], g["multiplicity"]) for g in groups if g["type"] == "planet"] == [
        ("planet", n - 1)]
    assert [g["type"] for g in groups].count("rotational") == 4
    planet = [g["frequency"] for g in groups if g["type"] == "planet"][0]
    assert planet == pytest.approx(f_planet, rel=1e-9)


def test_torsional_reduction_of_lin_parker_example(lp3):
    # Planet mode closed form on Lin & Parker's data: sqrt((5e8 + 5e8) / 0.61) / 2 pi.
    res = modal_analysis(lp3, "torsional")
    planet = [g for g in res.groups() if g["type"] == "planet"]
    assert len(planet) == 1 and planet[0]["multiplicity"] == 2
    assert planet[0]["frequency"] == pytest.approx(math.sqrt(1e9 / 0.61) / (2 * np.pi), rel=1e-9)
    assert float(res.frequencies[0]) < 1e-3


# --- relation to the twin's coordinates ------------------------------------------------------

def _twin_elastic_energy(lp, q):
    """Elastic energy (J) in the twin's coordinates, written from docs/conventions.md.

    q per body (sun, ring, carrier, planets): (x, y, theta) central, (zeta, eta, theta_p) planet.
    Ring mesh with the planet pushing the ring along n_rp: n_rp . (d_p - d_r).
    """
    n = lp.n_planets
    xs, ys, ts, xr, yr, tr, xc, yc, tc = (q[j] for j in range(9))
    d_s, d_r, d_c = jnp.stack([xs, ys]), jnp.stack([xr, yr]), jnp.stack([xc, yc])
    e = 0.5 * lp.k_bearing_sun * (xs**2 + ys**2) + 0.5 * lp.k_bearing_ring * (xr**2 + yr**2)
    e += 0.5 * lp.k_bearing_carrier * (xc**2 + yc**2) + 0.5 * lp.k_torsion_ring * tr**2
    a_s, a_r = lp.alpha_sp, lp.alpha_rp
    for i in range(n):
        z, h, tp = q[9 + 3 * i], q[10 + 3 * i], q[11 + 3 * i]
        psi = lp.planet_angles[i]
        e_r = jnp.stack([jnp.cos(psi), jnp.sin(psi)])
        e_t = jnp.stack([-jnp.sin(psi), jnp.cos(psi)])
        n_sp = jnp.cos(a_s) * e_t + jnp.sin(a_s) * e_r
        n_rp = jnp.sin(a_r) * e_r - jnp.cos(a_r) * e_t
        d_p = d_c + z * e_r + h * e_t
        dsp = n_sp @ (d_s - d_p) + lp.rb_sun * (ts - tc) + lp.rb_planet * (tp - tc)
        drp = n_rp @ (d_p - d_r) + lp.rb_ring * (tr - tc) - lp.rb_planet * (tp - tc)
        e += 0.5 * lp.k_sun_planet * dsp**2 + 0.5 * lp.k_ring_planet * drp**2
        e += 0.5 * lp.k_bearing_planet * (z**2 + h**2)
    return e


def test_twin_coordinates_hessian_equals_transformed_stiffness():
    lp = _paper_sim_like(3)
    t = lin_parker_transform(lp)
    q0 = jnp.zeros(18, dtype=jnp.float64)
    hess = jax.jit(jax.hessian(lambda q: _twin_elastic_energy(lp, q)))(q0)
    k_twin = t.T @ stiffness_matrix(lp) @ t
    np.testing.assert_allclose(np.asarray(k_twin), np.asarray(hess), rtol=1e-9,
                               atol=1e-9 * float(jnp.max(jnp.abs(hess))))


def test_rigid_body_mode_follows_gear_ratio():
    # In the twin's coordinates the 0 Hz mode is the free rotation with the ring held:
    # theta_s / theta_c = 1 + Zr / Zs, no translation, planets on their pins.
    lp = _paper_sim_like(3)
    res = modal_analysis(lp)
    assert float(res.frequencies[0]) < 1e-3
    q_twin = np.linalg.solve(np.asarray(lin_parker_transform(lp)), np.asarray(res.mode_shapes[:, 0]))
    q_twin /= q_twin[8]  # theta_c = 1
    assert q_twin[2] == pytest.approx(1 + 81 / 21, rel=1e-7)
    assert abs(q_twin[5]) < 1e-7
    np.testing.assert_allclose(q_twin[[0, 1, 3, 4, 6, 7]], 0.0, atol=1e-9)
    np.testing.assert_allclose(q_twin[[9, 10, 12, 13, 15, 16]], 0.0, atol=1e-9)
    # planet absolute rotation: theta_p = theta_c (1 - rb_r / rb_p) with the ring fixed
    np.testing.assert_allclose(q_twin[[11, 14, 17]], 1 - 81 / 30, rtol=1e-7)


def _twin_mesh_stiffness(lp, mesh):
    """Mesh stiffness in the twin's coordinates from dtwin.model.twin.mesh_deflections (its Jacobian)."""
    from dtwin.model.twin import Coords, mesh_deflections

    def deflections(v):
        q = Coords(sun_xy=v[0:2], theta_s=v[2], ring_xy=v[3:5], theta_r=v[5],
                   carrier_xy=v[6:8], theta_c=v[8], zeta=v[9::3], eta=v[10::3],
                   theta_p=v[11::3])
        d_sp, d_rp = mesh_deflections(lp, q)
        return d_sp if mesh == "sun" else d_rp

    jac = jax.jacfwd(deflections)(jnp.zeros(3 * (lp.n_planets + 3), dtype=jnp.float64))
    k = lp.k_sun_planet if mesh == "sun" else lp.k_ring_planet
    return np.asarray(k * jac.T @ jac)


def _modal_mesh_stiffness_in_twin_coordinates(lp, mesh):
    t = lin_parker_transform(lp)
    k_all = stiffness_matrix(lp)
    k_without = (stiffness_matrix(lp, k_sun_planet=0.0) if mesh == "sun"
                 else stiffness_matrix(lp, k_ring_planet=0.0))
    return np.asarray(t.T @ (k_all - k_without) @ t)


def test_twin_sun_mesh_agrees_with_lin_parker():
    # Cross-check with the dynamics (dtwin.model.twin): the sun-mesh stiffness it implies equals
    # Lin & Parker's, transformed to the twin's coordinates.
    lp = _paper_sim_like(3)
    k_twin = _twin_mesh_stiffness(lp, "sun")
    np.testing.assert_allclose(_modal_mesh_stiffness_in_twin_coordinates(lp, "sun"), k_twin,
                               atol=1e-9 * np.abs(k_twin).max())


def test_twin_ring_mesh_agrees_with_lin_parker():
    lp = _paper_sim_like(3)
    k_twin = _twin_mesh_stiffness(lp, "ring")
    np.testing.assert_allclose(_modal_mesh_stiffness_in_twin_coordinates(lp, "ring"), k_twin,
                               atol=1e-9 * np.abs(k_twin).max())


# --- derivatives -------------------------------------------------------------------------------

def test_frequency_derivative_matches_finite_differences(lp3, result3):
    # A simple mode: the rotational 1475.7 Hz mode (index 5: 0, 743 x2, 1102 x2, 1475.7).
    j = 5
    assert result3.mode_types[j] == "rotational" and result3.multiplicities[j] == 1
    k0 = 5e8
    grad = jax.grad(lambda k: natural_frequencies(lp3, k_sun_planet=k)[j])(
        jnp.asarray(k0, dtype=jnp.float64))
    h = 1e3
    fd = (float(natural_frequencies(lp3, k_sun_planet=k0 + h)[j])
          - float(natural_frequencies(lp3, k_sun_planet=k0 - h)[j])) / (2 * h)
    assert float(grad) == pytest.approx(fd, rel=1e-6)
    absolute = frequency_sensitivity(lp3, "k_sun_planet", relative=False)
    assert float(absolute[j]) == pytest.approx(fd, rel=1e-6)


def test_sensitivity_is_modal_strain_energy_and_sums_to_half(lp3, result3):
    # (k/f) df/dk = phi^T (k dK/dk) phi / (2 lambda): the strain-energy share in the sun meshes;
    # f is homogeneous of degree 1/2 in all stiffnesses, so the shares of all springs sum to 1/2.
    rel = np.asarray(frequency_sensitivity(lp3, "k_sun_planet"))
    phi = np.asarray(result3.mode_shapes)
    k_sp_part = np.asarray(stiffness_matrix(lp3) - stiffness_matrix(lp3, k_sun_planet=0.0))
    lam = (2 * np.pi * np.asarray(result3.frequencies)) ** 2
    energy = np.einsum("ij,ik,kj->j", phi, k_sp_part, phi)
    np.testing.assert_allclose(rel[1:], energy[1:] / (2 * lam[1:]), rtol=1e-6, atol=1e-10)
    assert rel[0] == 0.0
    names = ("k_sun_planet", "k_ring_planet", "k_bearing_sun", "k_bearing_ring",
             "k_bearing_carrier", "k_bearing_planet", "k_torsion_ring")
    total = sum(np.asarray(v) for v in frequency_sensitivities(lp3, names).values())
    np.testing.assert_allclose(total[1:], 0.5, rtol=1e-8)


def test_per_planet_mesh_stiffness_equals_scalar(lp3):
    f_scalar = natural_frequencies(lp3, k_sun_planet=4e8)
    f_vector = natural_frequencies(lp3, k_sun_planet=jnp.full(3, 4e8, dtype=jnp.float64))
    np.testing.assert_allclose(np.asarray(f_vector), np.asarray(f_scalar), rtol=1e-12)
    lp_b = replace(lp3, k_sun_planet=4e8)
    np.testing.assert_allclose(np.asarray(natural_frequencies(lp_b)), np.asarray(f_scalar),
                               rtol=1e-12)


# --- errors -----------------------------------------------------------------------------------

def test_errors_name_what_to_change(lp3):
    with pytest.raises(SpecError, match="torsional"):
        modal_analysis(lp3, "rotational")
    with pytest.raises(ParameterError, match="k_sun_planet"):
        frequency_sensitivity(lp3, "k_sun")
    with pytest.raises(SpecError, match="one per planet"):
        stiffness_matrix(lp3, k_sun_planet=jnp.ones(2, dtype=jnp.float64))


# --- CLI ----------------------------------------------------------------------------------------

def _invoke(args):
    """Run ``dtwin modes ARGS`` in-process (typer runs a lone command without its name)."""
    import typer.main
    from typer.testing import CliRunner

    import dtwin.cli.cmd_modes  # noqa: F401  (registers the command)
    from dtwin.cli.app import app

    cmd = typer.main.get_command(app)
    full = (["modes"] if hasattr(cmd, "commands") else []) + list(args)
    return CliRunner().invoke(app, full)


def test_cli_json_reproduces_lin_parker():
    import json

    r = _invoke(["--preset", "lin-parker", "--json"])
    assert r.exit_code == 0, r.output
    data = json.loads(r.stdout)
    rot = [m["frequency_hz"] for m in data["modes"] if m["type"] == "rotational"]
    trans = [m["frequency_hz"] for m in data["modes"] if m["type"] == "translational"]
    np.testing.assert_allclose(rot[1:], LP_ROTATIONAL[1:], rtol=5e-3)
    np.testing.assert_allclose(trans, LP_TRANSLATIONAL, rtol=5e-3)
    assert len(data["frequencies_hz"]) == 18


def test_cli_table_torsional_and_out_folder(tmp_path):
    import json

    r = _invoke(["--preset", "lin-parker", "--planets", "4", "--model", "torsional"])
    assert r.exit_code == 0, r.output
    assert "planet" in r.stdout and "rotational" in r.stdout
    # planet modes of the torsional reduction: sqrt(1e9 / 0.61) / 2 pi = 6444.0 Hz, three of them
    assert "6444.0" in r.stdout
    out = tmp_path / "res"
    r = _invoke(["--preset", "lin-parker", "--planets", "5", "--out", str(out)])
    assert r.exit_code == 0, r.output
    manifest = json.loads((out / "manifest.json").read_text())
    assert sorted(manifest["files"]) == ["modes.csv", "modes.json", "modes.npz", "modes.png"]
    assert (out / "modes.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    data = json.loads((out / "modes.json").read_text())
    assert sorted({m["multiplicity"] for m in data["modes"] if m["type"] == "planet"}) == [2]
    # a second run into the same folder is refused unless --force
    r = _invoke(["--preset", "lin-parker", "--out", str(out)])
    assert isinstance(r.exception, OutputExistsError) and "--force" in str(r.exception)
    r = _invoke(["--preset", "lin-parker", "--out", str(out), "--force"])
    assert r.exit_code == 0, r.output


def test_cli_paper_sim_mesh_frequency_and_mode_types():
    import json

    r = _invoke(["--preset", "paper-sim", "--json"])
    assert r.exit_code == 0, r.output
    data = json.loads(r.stdout)
    # paper Table 2: f_mesh = 500.1 Hz (computes to 500.3; agree within 1 %)
    assert data["f_mesh_hz"] == pytest.approx(500.1, rel=1e-2)
    # Lin & Parker's structure on the paper's gearbox (N = 3): 6 rotational, 6 translational
    # pairs, no planet modes, and the sensitivities of all springs of a mode sum to 1/2, so the
    # mesh share lies in [0, 1/2].
    kinds = [(m["type"], m["multiplicity"]) for m in data["modes"]]
    assert kinds.count(("rotational", 1)) == 6 and kinds.count(("translational", 2)) == 6
    assert len(kinds) == 12
    for m in data["modes"][1:]:
        share = m["sensitivity_k_sun_planet"] + m["sensitivity_k_ring_planet"]
        assert -1e-12 <= share <= 0.5 + 1e-9
        assert m["mesh_order"] == pytest.approx(m["frequency_hz"] / data["f_mesh_hz"])


def test_cli_refuses_bad_arguments():
    r = _invoke(["--json"])
    assert isinstance(r.exception, SpecError) and "--preset" in str(r.exception)
    r = _invoke(["--preset", "lin-parker", "--model", "rotational"])
    assert isinstance(r.exception, SpecError) and "torsional" in str(r.exception)
    r = _invoke(["--preset", "lin-parker", "--planets", "0"])
    assert isinstance(r.exception, SpecError) and "--planets" in str(r.exception)
    # issue 2: the simulation gearbox with 5 planets is refused (tip circles overlap)
    r = _invoke(["--preset", "paper-sim", "--planets", "5"])
    assert isinstance(r.exception, SpecError) and "tip diameter" in str(r.exception)


def test_plot_modes_one_stem_per_distinct_frequency():
    import matplotlib.pyplot as plt

    from dtwin.plotting.modes import plot_modes

    res = modal_analysis(lin_parker_example(4))
    fig = plot_modes(res, f_mesh=500.0, sample_rate=5000.0)
    top, bottom = fig.axes
    # Lin & Parker, N = 4: 6 rotational + 6 translational pairs + 3 planet frequencies
    assert len(top.collections) == 15
    assert [t.get_text() for t in top.get_yticklabels()] == ["rotational", "translational",
                                                              "planet"]
    assert "Hz" in bottom.get_xlabel() and "N = 4" in top.get_title()
    labels = top.get_legend_handles_labels()[1]
    assert "Nyquist 2500 Hz" in labels
    plt.close(fig)


def test_unequal_spacing_splits_pairs_and_mixes_types(lp3, result3):
    # Lin & Parker (2000, J. Sound Vib. 233:921): with unequally spaced planets the central
    # members' rotation and translation couple and the repeated (translational) frequencies
    # split. Equal spacing keeps the 12 translational entries as 6 pairs.
    trans = np.asarray(result3.of_type("translational"))
    np.testing.assert_allclose(trans, np.repeat(LP_TRANSLATIONAL, 2), rtol=5e-3)
    angles = jnp.asarray([0.0, 2 * np.pi / 3 + 0.1, 4 * np.pi / 3], dtype=jnp.float64)
    lp = eqx.tree_at(lambda m: m.planet_angles, lp3, angles)
    res = modal_analysis(lp)
    assert set(res.multiplicities) == {1}
    assert "mixed" in res.mode_types
    assert float(res.frequencies[0]) < 1e-3  # the rigid-body mode survives any spacing
