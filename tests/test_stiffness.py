"""Tests of dtwin.model.stiffness against ISO 6336-1 hand calculations, Fourier closed forms, numpy
FFTs and finite differences."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dtwin.errors import SpecError
from dtwin.model.stiffness import (
    cosine_series,
    mesh_stiffness_mean,
    mesh_stiffness_waveform,
    single_pair_from_mean,
    single_pair_stiffness,
    transmission_error,
)

F64 = jnp.float64

# ---------------------------------------------------------------------------------------------
# ISO 6336-1 method B: a textbook external spur pair worked by hand
# ---------------------------------------------------------------------------------------------
# z1 = 20, z2 = 40, x1 = +0.2, x2 = -0.1, b = 30 mm, alpha_Pn = 20 deg, h_fP/m_n = 1.25, beta = 0
# q' = 0.04723 + 0.15551/20 + 0.25791/40 - 0.00635*0.2 - 0.11654*0.2/20
#      - 0.00193*(-0.1) - 0.24188*(-0.1)/40 + 0.00529*0.2**2 + 0.00182*0.1**2
#    = 0.04723 + 0.0077755 + 0.00644775 - 0.00127 - 0.0011654 + 0.000193 + 0.0006047
#      + 0.0002116 + 0.0000182
#    = 0.06004535 mm*um/N
# c'_th = 1/q' = 16.654079 N/(mm*um)
# C_M = 0.8, C_R = 1, C_B = (1 + 0.5*(1.2 - 1.25)) * (1 - 0.02*(20 - 20)) = 0.975
# c' (no load factor) = 16.654079 * 0.8 * 1 * 0.975 = 12.990182 N/(mm*um)
#                     -> * 30 mm = 389.7054 N/um = 3.897054e8 N/m
# with F_t = 1500 N, K_A = 1.25: line load = 1500*1.25/30 = 62.5 N/mm < 100 N/mm
#   load factor (62.5/100)**0.25 = 0.8891397
#   c' = 12.990182 * 0.8891397 = 11.550086 N/(mm*um) -> * 30 mm -> 3.465026e8 N/m
# mean mesh stiffness at eps_alpha = 1.65: c_gamma_alpha = c' (0.75*1.65 + 0.25) = 1.4875 c'
#   = 17.180753 N/(mm*um) -> * 30 mm -> 5.154226e8 N/m
HAND_C_NOLOAD = 12.990182 * 30e-3 * 1e9  # N/m
HAND_C_LOAD = 11.550086 * 30e-3 * 1e9  # N/m
HAND_K_MEAN = 17.180753 * 30e-3 * 1e9  # N/m
PAIR = dict(x1=0.2, x2=-0.1)


def test_single_pair_hand_calculation_without_load_factor():
    c = single_pair_stiffness(20, 40, 0.030, **PAIR)
    np.testing.assert_allclose(float(c), HAND_C_NOLOAD, rtol=1e-6)


def test_single_pair_hand_calculation_with_load_factor():
    c = single_pair_stiffness(20, 40, 0.030, tangential_force=1500.0, K_A=1.25, **PAIR)
    np.testing.assert_allclose(float(c), HAND_C_LOAD, rtol=1e-6)


def test_mean_mesh_stiffness_hand_calculation():
    k = mesh_stiffness_mean(20, 40, 0.030, 1.65, tangential_force=1500.0, K_A=1.25, **PAIR)
    np.testing.assert_allclose(float(k), HAND_K_MEAN, rtol=1e-6)


def test_load_factor_is_one_above_100_N_per_mm():
    # 4500 N * 1.0 / 30 mm = 150 N/mm >= 100 N/mm: ISO applies no load factor
    c_hi = single_pair_stiffness(20, 40, 0.030, tangential_force=4500.0, **PAIR)
    np.testing.assert_allclose(float(c_hi), HAND_C_NOLOAD, rtol=1e-6)
    # exactly 100 N/mm is the boundary: factor 1
    c_100 = single_pair_stiffness(20, 40, 0.030, tangential_force=3000.0, **PAIR)
    c_none = single_pair_stiffness(20, 40, 0.030, **PAIR)
    np.testing.assert_allclose(float(c_100), float(c_none), rtol=1e-15)


def test_pinion_is_the_smaller_gear_for_external_pairs():
    # ISO's q' is not symmetric in gears 1 and 2; swapping the arguments must not change c'
    a = single_pair_stiffness(20, 40, 0.030, x1=0.2, x2=-0.1)
    b = single_pair_stiffness(40, 20, 0.030, x1=-0.1, x2=0.2)
    assert float(a) == pytest.approx(float(b), rel=1e-14)


def test_internal_mesh_takes_ring_zn_infinite():
    # planet 30 teeth in a ring of 81: q' = 0.04723 + 0.15551/30 (ring terms vanish, x = 0)
    q = 0.04723 + 0.15551 / 30
    expected = 1.0 / q * 0.8 * 0.975 * 20.0 * 1e6  # N/(mm um) * 20 mm * 1e6 -> N/m
    c = single_pair_stiffness(30, 81, 0.020, internal=True)
    np.testing.assert_allclose(float(c), expected, rtol=1e-12)
    # and it is stiffer than any external pair with the same pinion (concave ring flank)
    assert float(c) > float(single_pair_stiffness(30, 81, 0.020))


def test_helix_angle_and_basic_rack_factors():
    # beta = 15 deg: zn = z / cos^3(beta), and a factor cos(beta);
    # alpha_Pn = 25 deg, h_fP/m_n = 1.4: C_B = (1 + 0.5*(1.2 - 1.4)) * (1 - 0.02*(20 - 25)) = 0.99
    beta = math.radians(15.0)
    zn1, zn2 = 20 / math.cos(beta) ** 3, 40 / math.cos(beta) ** 3
    q = 0.04723 + 0.15551 / zn1 + 0.25791 / zn2
    expected = 1.0 / q * 0.8 * 0.99 * math.cos(beta) * 30.0 * 1e6
    c = single_pair_stiffness(
        20, 40, 0.030, beta=beta, pressure_angle=math.radians(25.0), hfp_over_mn=1.4
    )
    np.testing.assert_allclose(float(c), expected, rtol=1e-12)


def test_module2_20mm_steel_pair_is_a_few_1e8():
    # docs/references.md §4: module-2 steel gears of 20 mm face give mesh stiffnesses of a few 1e8 N/m
    # (the paper's simulation gearbox: sun 21, planet 30, ring 81; eps about 1.6 and 1.8)
    k_sp = float(mesh_stiffness_mean(21, 30, 0.020, 1.6))
    k_rp = float(mesh_stiffness_mean(30, 81, 0.020, 1.8, internal=True))
    for k in (k_sp, k_rp):
        assert 1e8 < k < 1e9
    # at ~15 N/mm line load (a few kW on a small bench) the load factor lowers it by ~0.62
    k_loaded = float(mesh_stiffness_mean(21, 30, 0.020, 1.6, tangential_force=300.0))
    np.testing.assert_allclose(k_loaded / k_sp, 0.15**0.25, rtol=1e-12)


def test_single_pair_stiffness_is_differentiable_in_force():
    # c' = c'_0 (F_t/(b 100 N/mm))^(1/4) below 100 N/mm, so d c'/dF_t = c'/(4 F_t);
    # at F_t = 1500 N, b = 30 mm, K_A = 1: line load 50 N/mm, c' = c'_0 * 0.5**0.25
    f = 1500.0
    dc = jax.grad(lambda ft: single_pair_stiffness(20, 40, 0.030, tangential_force=ft, **PAIR))(f)
    np.testing.assert_allclose(float(dc), HAND_C_NOLOAD * 0.5**0.25 / (4 * f), rtol=1e-6)


def test_bad_geometry_is_refused():
    with pytest.raises(SpecError, match="face_width"):
        single_pair_stiffness(20, 40, -0.01)
    with pytest.raises(SpecError, match="eps_alpha"):
        mesh_stiffness_waveform(0.1, 3e8, 2.3)


# ---------------------------------------------------------------------------------------------
# Waveform
# ---------------------------------------------------------------------------------------------
EPS = [1.3, 1.45, 1.6, 1.75, 1.9]


@pytest.mark.parametrize("eps", EPS)
def test_waveform_mean_is_exactly_k_mean(eps):
    # 256 equally spaced samples integrate a trigonometric polynomial of degree 12 exactly
    ph = jnp.arange(256, dtype=F64) / 256 + 0.123
    k = mesh_stiffness_waveform(ph, 3.2e8, eps)
    np.testing.assert_allclose(float(jnp.mean(k)), 3.2e8, rtol=1e-12)


@pytest.mark.parametrize("eps", EPS)
def test_double_contact_fraction_matches_contact_ratio(eps):
    # fraction of the cycle above the mid level c'(1 + 0.75/2) is eps - 1 (the rectangular wave's
    # double-contact fraction), up to the smoothing
    ph = jnp.arange(20000, dtype=F64) / 20000
    k = mesh_stiffness_waveform(ph, 3e8, eps)
    c1 = float(single_pair_from_mean(3e8, eps))
    frac = float(jnp.mean(k > 1.375 * c1))
    assert frac == pytest.approx(eps - 1.0, abs=0.01)


@pytest.mark.parametrize("eps", [1.45, 1.6, 1.75])
def test_single_to_double_ratio(eps):
    # mid-single-contact over mid-double-contact stiffness ~ 1/1.75 (conventions: c' / 1.75 c')
    d = eps - 1.0
    k = mesh_stiffness_waveform(jnp.asarray([d / 2, (1 + d) / 2], dtype=F64), 3e8, eps)
    assert float(k[1] / k[0]) == pytest.approx(1 / 1.75, rel=0.01)
    c1 = float(single_pair_from_mean(3e8, eps))
    np.testing.assert_allclose(np.asarray(k), [1.75 * c1, c1], rtol=0.01)
    # more harmonics converge to the rectangular wave
    k48 = mesh_stiffness_waveform(jnp.asarray([d / 2, (1 + d) / 2], dtype=F64), 3e8, eps,
                                  n_harmonics=48)
    np.testing.assert_allclose(np.asarray(k48), [1.75 * c1, c1], rtol=2e-3)


def test_waveform_matches_fft_of_rectangular_wave():
    # independent computation: numpy FFT of a finely sampled rectangular wave, truncated at 12
    # harmonics and multiplied by the Lanczos factors sinc(n/13)
    eps, kmean, m = 1.6, 3e8, 12
    c1 = kmean / (0.75 * eps + 0.25)
    n_s = 1 << 16
    phi = (np.arange(n_s) + 0.5) / n_s
    wave = np.where(phi < eps - 1, 1.75 * c1, c1)
    spec = np.fft.rfft(wave) / n_s
    n = np.arange(1, m + 1)
    sigma = np.sinc(n / (m + 1))
    x = np.linspace(0, 1, 257)[:-1]
    ref = spec[0].real + 2 * np.real(
        (sigma * spec[1:m + 1])[None, :]
        * np.exp(2j * np.pi * n[None, :] * (x[:, None] - 0.5 / n_s))
    ).sum(axis=1)
    got = np.asarray(mesh_stiffness_waveform(jnp.asarray(x), kmean, eps))
    np.testing.assert_allclose(got, ref, rtol=1e-4)


def test_waveform_is_band_limited():
    m = 12
    ph = jnp.arange(128, dtype=F64) / 128
    k = np.asarray(mesh_stiffness_waveform(ph, 3e8, 1.6, n_harmonics=m))
    spec = np.abs(np.fft.rfft(k)) / 128
    assert np.all(spec[m + 1:] < 1e-12 * 3e8)
    assert spec[1] > 1e-2 * 3e8


def test_waveform_broadcasts_over_phase_and_parameters():
    ph = jnp.linspace(0.0, 2.0, 7, dtype=F64)[:, None]
    kmean = jnp.asarray([2e8, 3e8, 4e8], dtype=F64)[None, :]
    k = mesh_stiffness_waveform(ph, kmean, 1.6)
    assert k.shape == (7, 3)
    # linear in k_mean, periodic in the phase with period 1
    np.testing.assert_allclose(np.asarray(k[:, 2] / k[:, 0]), 2.0, rtol=1e-14)
    np.testing.assert_allclose(np.asarray(k[0]), np.asarray(k[3]), rtol=1e-13)


def _central(f, x, h):
    return (f(x + h) - f(x - h)) / (2 * h)


@pytest.mark.parametrize("phase", [0.05, 0.31, 0.58, 0.97])
def test_waveform_gradients_match_finite_differences(phase):
    eps, kmean = 1.62, 3.1e8
    f_phase = lambda p: float(mesh_stiffness_waveform(p, kmean, eps))  # noqa: E731
    f_k = lambda k: float(mesh_stiffness_waveform(phase, k, eps))  # noqa: E731
    f_eps = lambda e: float(mesh_stiffness_waveform(phase, kmean, e))  # noqa: E731
    g = jax.grad(mesh_stiffness_waveform, argnums=(0, 1, 2))(
        jnp.asarray(phase, dtype=F64), jnp.asarray(kmean, dtype=F64), jnp.asarray(eps, dtype=F64)
    )
    np.testing.assert_allclose(float(g[0]), _central(f_phase, phase, 1e-6), rtol=1e-6,
                               atol=1e-7 * kmean)
    np.testing.assert_allclose(float(g[1]), _central(f_k, kmean, 1e2), rtol=1e-8)
    np.testing.assert_allclose(float(g[2]), _central(f_eps, eps, 1e-6), rtol=1e-6,
                               atol=1e-7 * kmean)


def _direct_series(x, coef):
    n = jnp.arange(1, coef.shape[-1] + 1, dtype=F64)
    return jnp.sum(coef * jnp.cos(2.0 * jnp.pi * n * x[..., None]), axis=-1)


@pytest.mark.parametrize("m", [1, 2, 12, 200])
def test_cosine_series_recurrence_matches_direct_sum(m):
    """The angle-addition recurrence (one cos and sin per phase) against m cosines: rounding
    only, growing at most like m ulp of the amplitude."""
    rng = np.random.default_rng(m)
    x = jnp.asarray(rng.uniform(-0.5, 0.5, 64))
    coef = jnp.asarray(rng.normal(size=(64, m)))
    got, want = cosine_series(x, coef), _direct_series(x, coef)
    scale = float(jnp.sum(jnp.abs(coef), axis=-1).max())
    assert float(jnp.max(jnp.abs(got - want))) <= 4e-16 * m * scale + 1e-15


def test_cosine_series_derivatives_match_autodiff_of_direct_sum():
    """The custom JVP rule (phase and coefficient tangents, under vmap as jacfwd uses it)
    and a second derivative through it, against JAX's own rules on the direct sum."""
    rng = np.random.default_rng(0)
    x = jnp.asarray(rng.uniform(-0.5, 0.5, 6))
    coef = jnp.asarray(rng.normal(size=(6, 12)))
    for argnums in (0, 1, (0, 1)):
        got = jax.jacfwd(cosine_series, argnums=argnums)(x, coef)
        want = jax.jacfwd(_direct_series, argnums=argnums)(x, coef)
        for g, w in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
            np.testing.assert_allclose(g, w, rtol=1e-12, atol=1e-12)
    g_rev = jax.grad(lambda c: jnp.sum(cosine_series(x, c) ** 2))(coef)
    w_rev = jax.grad(lambda c: jnp.sum(_direct_series(x, c) ** 2))(coef)
    np.testing.assert_allclose(g_rev, w_rev, rtol=1e-12, atol=1e-12)
    h_got = jax.hessian(lambda p: jnp.sum(cosine_series(p, coef)))(x)
    h_want = jax.hessian(lambda p: jnp.sum(_direct_series(p, coef)))(x)
    np.testing.assert_allclose(h_got, h_want, rtol=1e-11, atol=1e-10)


def test_single_pair_from_mean_inverts_iso_mean():
    c1 = single_pair_stiffness(21, 30, 0.020)
    k = mesh_stiffness_mean(21, 30, 0.020, 1.57)
    np.testing.assert_allclose(float(single_pair_from_mean(k, 1.57)), float(c1), rtol=1e-14)


# ---------------------------------------------------------------------------------------------
# Transmission error
# ---------------------------------------------------------------------------------------------
def test_transmission_error_closed_form_and_zero_mean():
    ph = jnp.arange(64, dtype=F64) / 64
    amp = 20e-6  # m, docs/references.md §4's typical amplitude
    e1 = transmission_error(ph, amp)
    np.testing.assert_allclose(np.asarray(e1), amp * np.sin(2 * np.pi * np.asarray(ph)),
                               atol=1e-20)
    e = transmission_error(ph, amp, harmonics=(1.0, 0.3, 0.1), phases=(0.0, np.pi / 2, 1.0))
    x = np.asarray(ph)
    ref = amp * (np.sin(2 * np.pi * x) + 0.3 * np.cos(4 * np.pi * x)
                 + 0.1 * np.sin(6 * np.pi * x + 1.0))
    np.testing.assert_allclose(np.asarray(e), ref, atol=1e-20)
    assert abs(float(jnp.mean(e))) < 1e-15 * amp
    with pytest.raises(SpecError, match="phases"):
        transmission_error(ph, amp, harmonics=(1.0, 0.5), phases=(0.0,))


# ---------------------------------------------------------------------------------------------
# Figure and CLI (`dtwin stiffness`)
# ---------------------------------------------------------------------------------------------
def test_plot_mesh_stiffness_draws_the_given_curves():
    import matplotlib.pyplot as plt

    from dtwin.plotting.stiffness import plot_mesh_stiffness

    x = np.linspace(0.0, 5.0, 201)
    k_sp = np.asarray(mesh_stiffness_waveform(jnp.asarray(x), 3e8, 1.6))
    k_rp = np.asarray(mesh_stiffness_waveform(jnp.asarray(x), 4e8, 1.8))
    fig = plot_mesh_stiffness(x, k_sp, k_rp, k_sun_planet_faulty=0.9 * k_sp,
                              k_ring_planet_faulty=k_rp, zoom=(1.0, 3.0), fault_label="test fault",
                              title="t")
    axes = fig.axes
    assert len(axes) == 4
    assert "1e8 N/m" in axes[0].get_ylabel() and "mesh cycles" in axes[2].get_xlabel()
    lines = axes[0].get_lines()
    np.testing.assert_allclose(lines[0].get_ydata(), k_sp / 1e8)  # plotted in units of 1e8 N/m
    np.testing.assert_allclose(lines[1].get_ydata(), 0.9 * k_sp / 1e8)
    assert [t.get_text() for t in axes[0].get_legend().get_texts()] == ["healthy", "test fault"]
    assert axes[1].get_xlim() == (1.0, 3.0)
    plt.close(fig)


def _run_cli(args, capsys):
    from dtwin.cli import main

    main(args)
    return capsys.readouterr().out


def test_cli_stiffness_json_against_iso_hand_calculation(capsys):
    import json

    pytest.importorskip("dtwin.spec")
    out = _run_cli(["stiffness", "--preset", "paper-sim", "--fault", "sun:missing_tooth:0.5",
                    "--json"], capsys)
    rep = json.loads(out)
    # Hand calculation for the paper-sim preset (dtwin/spec/presets/paper-sim.toml: 21/30/81, 20 mm face,
    # 50 N*m at the carrier): T_sun = 50 * 21/102 = 10.294 N*m, F_t = T_sun/(3 * 0.021 m)
    # = 163.40 N, line load 8.170 N/mm -> load factor 0.0817**0.25 = 0.53463;
    # q' = 0.04723 + 0.15551/21 + 0.25791/30 = 0.063235 -> c'_th = 15.8140 N/(mm um);
    # c' = 15.8140 * 0.8 * 0.975 * 0.53463 = 6.5946 N/(mm um) -> * 20 mm -> 1.3189e8 N/m
    t_sun = 50.0 * 21 / 102
    f_t = t_sun / (3 * 0.021)
    lf = (f_t / 20.0 / 100.0) ** 0.25
    q = 0.04723 + 0.15551 / 21 + 0.25791 / 30
    c_hand = 1 / q * 0.8 * 0.975 * lf * 20.0 * 1e6
    sp = rep["meshes"]["sun_planet"]
    np.testing.assert_allclose(sp["c_single"], c_hand, rtol=1e-9)
    np.testing.assert_allclose(sp["c_double"], 1.75 * c_hand, rtol=1e-9)
    np.testing.assert_allclose(sp["k_mean"], c_hand * (0.75 * sp["eps"] + 0.25), rtol=1e-9)
    # a sun tooth with half its face width gone removes half a pair, only from the sun mesh
    np.testing.assert_allclose(sp["max_loss"], 0.5 * c_hand, rtol=1e-6)
    assert rep["meshes"]["ring_planet"]["max_loss"] == 0.0
    assert rep["faults"][0]["location"] == "sun" and rep["faults"][0]["severity"] == 0.5


@pytest.mark.filterwarnings("ignore:z_ring = 84")  # the bench needs profile shift (expected)
def test_cli_stiffness_out_folder(tmp_path, capsys):
    import json

    pytest.importorskip("dtwin.spec")
    out = tmp_path / "res"
    _run_cli(["stiffness", "--preset", "paper-bench", "--fault", "planet:missing_tooth:1.0:2:2",
              "--out", str(out)], capsys)
    manifest = json.loads((out / "manifest.json").read_text())
    # the table, the arrays (CSV and NPZ, tests/test_cli_arrays.py) and the figure
    assert set(manifest["files"]) == {"stiffness.json", "stiffness.csv", "stiffness.npz",
                                      "stiffness.png"}
    data = json.loads((out / "stiffness.json").read_text())
    assert data["planet"] == 2  # the planet of the planet fault is the one shown
    # a whole planet tooth gone: both meshes lose one pair (c') during each contact of the tooth,
    # which lasts eps cycles and recurs every Zp = 31 mesh cycles (one planet revolution
    # relative to the carrier); Zp + 4 cycles are shown
    curves = {k: np.asarray(v) for k, v in data["curves"].items()}
    x = curves["mesh_cycles"]
    for mesh in ("sun_planet", "ring_planet"):
        key = "k_" + mesh
        loss = curves[key] - curves[key + "_faulty"]
        c1 = data["meshes"][mesh]["c_single"]
        assert loss.max() == pytest.approx(c1, rel=0.03)
        above = loss > 0.5 * c1
        starts = x[1:][above[1:] & ~above[:-1]]
        assert 1 <= len(starts) <= 2
        if len(starts) == 2:
            assert starts[1] - starts[0] == pytest.approx(31.0, abs=0.05)
        cycles_lost = loss.sum() / 40 / c1  # 40 samples per mesh cycle
        assert cycles_lost == pytest.approx(len(starts) * data["meshes"][mesh]["eps"], rel=0.05)
    assert (out / "stiffness.png").stat().st_size > 10_000
