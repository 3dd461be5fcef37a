"""dtwin.identify.fit / severity / CLI against records of known truth (issue 7 "Tests that must pass").

No inverse crime in the CI form: the truth's mesh-stiffness waveform keeps 30 Fourier harmonics
(sharper single/double-contact steps) and carries a 0.5 µm transmission error, the fitted twin
keeps the spec's 12 harmonics and has no transmission error; and the bench runs 1 % slow
(1782 rpm, docs/references.md §1) while the spec says 1800 rpm, so the speed is estimated from the
record. The model-form error shows up as a larger residual variance (wider intervals) and a bias
that the tolerance below documents.

A *translational* truth fitted with the torsional twin at 5 kHz is NOT used: the translational
modes (0.9, 1.8, 2.4, 3.3 kHz for this gearbox) lie inside the 5 kHz record's band and the
ring's translation reaches the sensor, so the torsional twin cannot reproduce those spectra
(measured: severity 0.07 for a true 0.5, not converged in 40 steps — and flagged NOT DETERMINED
by item 6's criterion, i.e. not reported as precise). Fit the translational twin to such data.
"""

import dataclasses
import json

import numpy as np
import pytest

from dtwin.model.faults import MissingTooth
from dtwin.simulation.simulate import DAQ, simulate
from dtwin.spec import preset
from dtwin.spec.build import build_twin

TRUE_SEVERITY = 0.5
F_SUN_TRUE = 29.7  # 1782 rpm, 1 % below the spec's 1800 rpm


@pytest.fixture(scope="module")
def spec():
    return preset("paper-sim")


@pytest.fixture(scope="module")
def truth_record(spec):
    from dtwin.model.parts.imperfections import TransmissionError

    tw = build_twin(spec, kind="torsional", f_sun=F_SUN_TRUE, n_harmonics=30,
                    faults=(MissingTooth(TRUE_SEVERITY, location="sun"),),
                    extra_parts=(TransmissionError(np.float64(5e-7)),))
    return simulate(tw, duration=0.5, f_sun=F_SUN_TRUE, daq=DAQ(sample_rate=5000.0, snr_db=10.0),
                    discard=0.05, seed=3).to_record()


@pytest.fixture(scope="module")
def severity_fit(truth_record, spec):
    from dtwin.identify.severity import estimate_severity

    # the truth is torsional: the severity's default twin is translational (SEVERITY_KIND)
    return estimate_severity(truth_record, spec, "sun", initial_severity=0.35, max_steps=25,
                             kind="torsional", method="spectrum")  # the fit's internals


def test_speed_estimated_before_fit(severity_fit):
    op = severity_fit.fit.operating_points[0]
    assert op["method"] == "spectrum"
    assert abs(op["f_sun"] - F_SUN_TRUE) / F_SUN_TRUE < 5e-4


def test_severity_from_translational_truth(severity_fit):
    """Sharper-waveform truth with transmission error, 0.5 s at 5 kHz, 10 dB SNR, start 30 % off."""
    est = severity_fit
    assert est.fit.converged, est.fit.message
    lo, hi = est.interval
    # measured: 0.402, 95 % [0.300, 0.515], 9 LM steps. The sharper waveform and the
    # transmission error of the truth put broadband mesh-harmonic content into the bands that
    # the fitted twin (12 harmonics, no TE) explains partly by a smaller fault: a model-form
    # bias of about -0.1 on top of the noise (sigma ~ 0.055 for 0.5 s at 10 dB). Tolerance 0.15;
    # the interval (which counts the misfit as noise, not as bias) is informative, not a bound.
    assert abs(est.severity - TRUE_SEVERITY) < 0.15, est
    assert hi - lo < 0.3, est
    assert est.determined
    # the loss went down from the start
    h = est.fit.loss_history
    assert h[-1] < h[0]


def test_fit_uses_the_solvers_last_residuals_and_jacobian(severity_fit):
    """The fit takes r and J at the optimum from optimistix's last accepted step (no further
    simulation): they equal a fresh evaluation there, to the ODE solver's noise."""
    import jax.numpy as jnp

    from dtwin.identify.residuals import point_groups
    from dtwin.identify.solve import jacobian_at
    from dtwin.identify.uncertainty import analyse

    res = severity_fit.fit
    prob = res.problem
    r, J = jacobian_at(jnp.asarray(res.theta), prob)
    np.testing.assert_allclose(res.residuals, np.asarray(r), atol=1e-3 * np.sqrt(np.mean(r**2)))
    fresh = analyse(prob.pset, res.theta, np.asarray(r), np.asarray(J),
                    point_groups(prob.observations), n_profiled_gains=prob.n_profiled_gains)
    np.testing.assert_allclose(res.uncertainty.std, fresh.std, rtol=1e-2)


def test_fitted_spectra_read_from_the_residuals(severity_fit):
    """The figures' fitted levels come from the residuals at the optimum, with nothing
    simulated again: they give back the fit's loss exactly, and agree with a fresh simulation of
    the twin at the optimum (op by op, not compiled as in the fit: 1 % leaves room for that
    difference, well below a figure's resolution); residuals holding a failed point fall back
    to the simulation."""
    import dataclasses

    res = severity_fit.fit
    prob = res.problem
    read = res.spectra()
    (obs,) = prob.observations
    (f, meas, fitted) = read[0]
    r = obs.weight * (np.log(fitted) - np.log(meas))
    priors = res.residuals[len(r) + (obs.env_meas.shape[0] if obs.env_weight else 0):]
    assert 0.5 * (np.sum(r**2) + np.sum(priors**2)) == pytest.approx(res.loss, rel=1e-9)
    simulated = dataclasses.replace(res, residuals=None).spectra()
    np.testing.assert_array_equal(simulated[0][0], f)
    np.testing.assert_allclose(simulated[0][1], meas, rtol=1e-12)
    np.testing.assert_allclose(simulated[0][2], fitted, rtol=1e-2)
    failed = res.residuals.copy()
    failed[0] = 30.0  # residuals.FAILED_RESIDUAL: a point whose model value was not finite
    assert dataclasses.replace(res, residuals=failed)._levels_from_residuals() is None


def test_gauss_newton_step_in_sigma_matches_least_squares():
    """The statistical stopping rule's step (Gram–Schmidt, no LAPACK) equals numpy's least
    squares, and a dependent column gets no step."""
    import jax.numpy as jnp

    from dtwin.identify.stopping import _gauss_newton_step

    rng = np.random.default_rng(0)
    J = rng.normal(size=(200, 4)) * np.array([1.0, 1e3, 1e-3, 5.0])
    r = rng.normal(size=200)
    in_sigma, delta = _gauss_newton_step(jnp.asarray(r), jnp.asarray(J))
    d0 = np.linalg.lstsq(J, -r, rcond=None)[0]
    np.testing.assert_allclose(np.asarray(delta), d0, rtol=1e-9)
    s2 = np.sum(r * r) / (200 - 4)
    assert abs(float(in_sigma) - np.sqrt(np.sum((J @ d0) ** 2) / s2)) < 1e-9
    J2 = np.c_[J, J[:, 0] + J[:, 1]]
    _, d2 = _gauss_newton_step(jnp.asarray(r), jnp.asarray(J2))
    assert float(d2[-1]) == 0.0


def _noisy_decay_fit(theta0: float, max_steps: int = 60):
    """LM (the fit's solver, `sigma_tol` 0.1) on an exponential decay whose residuals carry
    ODE-solver-like noise: a chaotic function of θ (amplitude 0.4 × the data's noise) that the
    Jacobian does not see. Returns (θ, steps, converged) and the noise-free optimum with its
    standard error."""

    import jax
    import jax.numpy as jnp
    from scipy.optimize import least_squares

    from dtwin.identify.solve import least_squares as solve_least_squares
    from dtwin.identify.stopping import make_solver

    rng = np.random.default_rng(1)
    x = np.linspace(0.0, 1.0, 400)
    y = np.exp(-2.1 * x) + 0.05 * rng.normal(size=x.size)
    phase = rng.uniform(0.0, 2.0 * np.pi, x.size)

    def residuals(theta, _):
        noise = 0.02 * jnp.sin(1e7 * theta[0] + phase)
        return jnp.exp(-3.0 * theta[0] * x) + jax.lax.stop_gradient(noise) - y, None

    solver = make_solver("lm", 1e-3, 1e-3, 0.1, history=max_steps + 1)
    th, ok, steps = solve_least_squares(residuals, solver, jnp.asarray([theta0]), None,
                                        "fwd", max_steps)[:3]
    clean = least_squares(lambda t: np.exp(-3.0 * t[0] * x) - y, [theta0], xtol=1e-14)
    J = clean.jac
    se = float(np.sqrt(np.sum(clean.fun ** 2) / (x.size - 1) / (J[:, 0] @ J[:, 0])))
    return float(th[0]), int(steps), bool(ok), float(clean.x[0]), se


def test_a_fit_stalled_in_the_solvers_noise_stops(monkeypatch):
    """Where the ODE solver's noise in the loss exceeds what a move of 0.1 standard errors
    changes, the statistical stop is met only by chance: the fit sits at its minimum and its
    steps aim at the noise. The stall stop ends it (4 evaluations without a gain of
    ½ (0.1 s)², the step within one standard error) near the noise-free optimum; with the
    stall stop switched off the same fits run on for tens of steps (seen on 4 s records:
    minimum at step 3, stopped at step 30)."""
    import importlib

    stopping = importlib.import_module("dtwin.identify.stopping")
    starts = (0.3, 1.0, 1.2)  # truth 0.7; fits whose statistical stop was not met by chance
    with_stall = [_noisy_decay_fit(t0) for t0 in starts]
    monkeypatch.setattr(stopping, "_STALL_EVALUATIONS", 10**6)
    without = [_noisy_decay_fit(t0) for t0 in starts]
    for (th, steps, ok, best, se), (_, steps_off, _, _, _) in zip(with_stall, without,
                                                                   strict=True):
        assert ok and steps <= 12, (steps, th)
        assert abs(th - best) < 0.5 * se, (th, best, se)
        assert steps_off >= 2 * steps, (steps, steps_off)
    assert max(w[1] for w in without) >= 25


def test_starts_refined_by_vmap_and_by_map_agree(truth_record, spec):
    """Two starts refined in one call, batched by `vmap` (a GPU's way) and by `lax.map` (the
    CPU default): the same optimum (to the ODE solver's noise) and no deadlock of batched
    linear algebra inside the loop (the stopping rule uses no LAPACK call)."""
    from dtwin.identify.fit import fit

    kw = dict(f_sun=F_SUN_TRUE, starts=[{"sun_fault": 0.35}, {"sun_fault": 0.65}], refine=2,
              max_steps=15, uncertainty=False)
    a = fit(truth_record, spec, ["sun_fault"], batch="vmap", **kw)
    b = fit(truth_record, spec, ["sun_fault"], batch="map", **kw)
    va = [r["values"]["sun_fault"] for r in a.refined]
    vb = [r["values"]["sun_fault"] for r in b.refined]
    np.testing.assert_allclose(va, vb, atol=5e-3)
    assert abs(va[0] - va[1]) < 0.02, va


def test_gain_column_outside_the_ode_is_exact(truth_record, spec):
    """With the sensor gain free, only the twin's parameters ride through the ODE
    (`dtwin.identify.solve.value_and_jacfwd`); the chain rule gives the Jacobian of forward mode through everything."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from dtwin.identify.problem import make_problem
    from dtwin.identify.residuals import Features
    from dtwin.identify.solve import jacobian_at

    prob, _ = make_problem(truth_record, spec, ["sun_fault", "sensor_gain"], f_sun=F_SUN_TRUE,
                           initial={"sun_fault": 0.4}, features=Features(gain="fixed"))
    assert prob.pset.twin_indices == (0,)
    theta = jnp.asarray([0.1, -0.2])
    r, J = jacobian_at(theta, prob)

    def both(t):
        x = prob.residuals(t)
        return x, x

    J_all, r_all = eqx.filter_jit(lambda t: jax.jacfwd(both, has_aux=True)(t))(theta)
    scale = np.sqrt(np.mean(np.asarray(r_all) ** 2))
    np.testing.assert_allclose(np.asarray(r), np.asarray(r_all), atol=1e-3 * scale)
    for k in range(2):
        col, ref = np.asarray(J[:, k]), np.asarray(J_all[:, k])
        assert np.max(np.abs(col - ref)) < 1e-3 * np.max(np.abs(ref)), k


def test_cli_identify_json_and_outputs(tmp_path, truth_record):
    # (it asked for the module's severity fit, which it never read: a worker that ran it alone
    # paid for that estimate too)
    from dtwin.cli import main
    from dtwin.io.output import OutputFolder

    folder = OutputFolder(tmp_path / "rec", force=True)
    folder.write_record("rec.dtwin.h5", truth_record)
    rec = str(tmp_path / "rec" / "rec.dtwin.h5")
    # a tooth fault's depth alone: read as `dtwin severity` reads it (the sideband ratio), its
    # interval reported beside the value, no solver loss to draw
    out = tmp_path / "depth"
    main(["identify", rec, "--preset", "paper-sim", "--free", "sun_fault", "--out", str(out)])
    data = json.loads((out / "identify.json").read_text())
    assert data["names"] == ["sun_fault"]
    assert data["severity"]["interval_method"].startswith("line ratio")
    assert data["intervals_95"]["sun_fault"] == data["severity"]["interval_95"]
    assert data["values"]["sun_fault"] == data["severity"]["severity"]
    manifest = json.loads((out / "manifest.json").read_text())
    assert {"identify.json", "spectrum_fit.png", "report.html"} <= set(manifest["files"])
    assert "loss.png" not in manifest["files"]
    # a parameter the spectrum fit estimates: its covariance, correlations and loss history
    out = tmp_path / "fit"
    main(["identify", rec, "--preset", "paper-sim", "--free", "zeta_mesh", "--max-steps", "3",
          "--out", str(out)])
    data = json.loads((out / "identify.json").read_text())
    assert data["names"] == ["zeta_mesh"]
    assert "intervals_95" in data and data["loss_history"] and "correlation" in data["uncertainty"]
    manifest = json.loads((out / "manifest.json").read_text())
    assert {"identify.json", "spectrum_fit.png", "loss.png"} <= set(manifest["files"])


def test_cli_unknown_free_name_exit_code(capsys):
    from dtwin.cli import main

    with pytest.raises(SystemExit) as e:
        main(["identify", "no-such-file.h5", "--preset", "paper-sim", "--free", "k_sun_planit"])
    assert e.value.code == 2
    assert "k_sun_planet" in capsys.readouterr().err


# ------------------------------------------------------- run-up, CI form (issue 7, claim 1)
# The torsional modes of paper-sim (Twin.linear_stiffness / mass_matrix, ring support 6e6
# N·m/rad): 3.55, 6.83 (×2), 8.25, 12.08 kHz; +10 % k_ring_planet moves them by +1.3, +2.9,
# +3.3, +0.2 %, +10 % k_sun_planet by +0.0, +2.1, +0.2, +4.7 %. A run-up 35 → 42 Hz (nominal;
# the bench runs 1 % slow) sweeps the 10th and 11th mesh harmonics across the 6.83 kHz pair and
# the 12th across 8.25 kHz. Relative standard deviations at the truth (Jacobian, 1 s of this
# sweep, 10 dB SNR): k_ring_planet 0.009, zeta_mesh 0.038, k_sun_planet 0.046, severity 0.011
# (absolute) — √2 more for 0.5 s. So k_ring_planet, the damping and the severity are asserted at
# the claim's tolerances; k_sun_planet (mostly the 12 kHz mode, above 0.45 × 25.6 kHz) at 15 %.
RUNUP_NOMINAL = (35.0, 42.0)


@pytest.fixture(scope="module")
def runup_fit(spec):
    from dtwin.identify.fit import fit
    from dtwin.identify.residuals import drive_at

    truth_tw = build_twin(spec, kind="torsional", faults=(MissingTooth(0.5, location="sun"),))
    T, discard = 0.5, 0.05
    f0, f1 = (0.99 * f for f in RUNUP_NOMINAL)  # 1 % below the nominal ramp
    rec = simulate(drive_at(truth_tw, f0, f1, T, discard), duration=T,
                   f_sun=f0 - (f1 - f0) / T * discard,
                   daq=DAQ(sample_rate=25600.0, snr_db=10.0), discard=discard, seed=5).to_record()
    truth = {"sun_fault": 0.5, "k_sun_planet": float(truth_tw.lp.k_sun_planet),
             "k_ring_planet": float(truth_tw.lp.k_ring_planet), "zeta_mesh": 0.07}
    signs = [(+1, -1, +1, -1), (-1, +1, -1, +1), (+1, +1, -1, -1)]
    starts = [{n: truth[n] * (1 + 0.3 * sg) for n, sg in zip(truth, s, strict=True)}
              for s in signs]
    # three starts 30 % off, refined in ONE batched optimistix call (vmap on a GPU, lax.map on a CPU)
    res = fit(rec, spec, list(truth), initial=starts[0], starts=starts, refine=3,
              runup=(0.9 * RUNUP_NOMINAL[0], 1.1 * RUNUP_NOMINAL[1]), max_steps=20)
    return res, truth


def _runup_ok(values, truth, k_sun_tol):
    return (abs(values["k_ring_planet"] / truth["k_ring_planet"] - 1) < 0.05
            and abs(values["k_sun_planet"] / truth["k_sun_planet"] - 1) < k_sun_tol
            and abs(values["zeta_mesh"] / truth["zeta_mesh"] - 1) < 0.2
            and abs(values["sun_fault"] - truth["sun_fault"]) < 0.05)


def test_runup_sweep_recovers_mesh_parameters(runup_fit):
    """0.5 s run-up at 25.6 kHz across the 6.83/8.25 kHz modes, 10 dB SNR, speed 1 % off,
    three starts 30 % off in one batched call: each start within the tolerances; the scan of
    the stiffnesses finds no other minimum."""
    res, truth = runup_fit
    print(res.table(), *res.refined, sep="\n")  # shown with -s: the measured values
    op = res.operating_points[0]
    assert abs(op["f_sun_start"] / (0.99 * RUNUP_NOMINAL[0]) - 1) < 2e-3, op
    good = [_runup_ok(r["values"], truth, 0.15) for r in res.refined]
    assert sum(good) >= 2, res.refined
    assert _runup_ok(res.values, truth, 0.15), res.table()
    assert not res.not_determined, res.not_determined
    # the stiffnesses' loss scanned a decade each side: one minimum, nothing lower
    assert res.uncertainty.scanned == ("k_sun_planet", "k_ring_planet")
    assert not res.relocations, res.relocations


# ----------------------------------------------------------------------- full forms (slow)
@pytest.mark.slow
def test_runup_recovers_mesh_parameters_from_30pc_off(spec):
    """Full form: run-up 35 → 42 Hz nominal (the bench 1 % slow) in 4 s at 25.6 kHz, 10 dB SNR,
    sun fault 0.5; 5 seeded random starts 30 % off, refined in one batched call: at least 4
    within 5 % (both stiffnesses), 20 % (damping), 0.05 (severity).

    Record length from the Jacobian at the truth: k_sun_planet's relative standard deviation
    is 0.046 for 1 s of this sweep (its 12 kHz mode lies above 0.45 × 25.6 kHz; the 6.83 kHz
    pair carries what there is), so "within 5 %" at ~95 % needs ≈ 4 s (a wider sweep, 30 → 45 Hz,
    gives 0.044 but its speed profile was estimated 1.5 % off). Measured (2026-11-22, quiet
    2-core CPU, starts mapped one after another, 467 s): all 5 starts end at one point,
    severity −0.020, k_sun_planet +3.3 %, k_ring_planet −0.2 %, zeta_mesh +5.3 %, in 5–11 LM
    steps."""
    from dtwin.identify.fit import fit
    from dtwin.identify.residuals import drive_at

    truth_tw = build_twin(spec, kind="torsional", faults=(MissingTooth(0.5, location="sun"),))
    T, discard, nominal = 4.0, 0.05, RUNUP_NOMINAL
    f0, f1 = (0.99 * f for f in nominal)
    rec = simulate(drive_at(truth_tw, f0, f1, T, discard), duration=T,
                   f_sun=f0 - (f1 - f0) / T * discard,
                   daq=DAQ(sample_rate=25600.0, snr_db=10.0), discard=discard, seed=5).to_record()
    truth = {"sun_fault": 0.5, "k_sun_planet": float(truth_tw.lp.k_sun_planet),
             "k_ring_planet": float(truth_tw.lp.k_ring_planet), "zeta_mesh": 0.07}
    rng = np.random.default_rng(11)
    starts = [{n: v * (1 + 0.3 * rng.choice([-1, 1])) for n, v in truth.items()}
              for _ in range(5)]
    res = fit(rec, spec, list(truth), initial=starts[0], starts=starts, refine=5,
              runup=(0.9 * nominal[0], 1.1 * nominal[1]), max_steps=40)
    good = sum(_runup_ok(r["values"], truth, 0.05) for r in res.refined)
    for r in res.refined:  # shown with -s: each start's relative errors and steps
        print({n: round(r["values"][n] / truth[n] - 1, 4) if n != "sun_fault"
               else round(r["values"][n] - truth[n], 4) for n in truth}, r["steps"])
    assert good >= 4, res.refined


@pytest.mark.slow
def test_severity_series_in_order(spec):
    from dtwin.identify.severity import severity_series

    truth = [0.1, 0.3, 0.5, 0.7, 0.9]
    recs = []
    for i, s in enumerate(truth):
        tw = build_twin(spec, kind="torsional", faults=(MissingTooth(s, location="sun"),))
        recs.append(simulate(tw, duration=1.0, f_sun=30.0, daq=DAQ(sample_rate=5000.0,
                             snr_db=20.0), discard=0.05, seed=20 + i).to_record())
    series = severity_series(recs, spec, "sun", f_sun=30.0, kind="torsional")
    v, lo, hi = series.trajectory("sun_fault")
    assert np.all(np.diff(v) > 0)
    assert np.all(np.abs(v - truth) < 0.05), v


def test_a_fit_settles_its_tiled_response_before_solving():
    """A fit tiles one period of the gear set inside its compiled solve, where nothing can be
    checked: the solve returns the periodicity defect of its last accepted point, and where a
    slowly decaying transient outlasted the settling time (the tiles' joins in the spectrum) the
    fit runs again, settling longer (the fitted severity 0.498, as a fit of the whole record gives,
    for a true 0.5). The paper's gearbox keeps its default settling time."""
    import jax.numpy as jnp
    from _gearboxes import SLOW_SETTLING

    from dtwin.identify.fit import fit, make_problem
    from dtwin.spec import load_spec
    from dtwin.spec.build import daq_from_spec

    slow = load_spec(SLOW_SETTLING)
    twin = build_twin(slow, kind="torsional", f_sun=20.0,
                      faults=(MissingTooth(0.5, location="sun"),))
    rec = simulate(twin, duration=1.5, f_sun=20.0, discard=0.3,
                   daq=daq_from_spec(slow, snr_db=30.0)).to_record()
    res = fit(rec, slow, ["sun_fault"], kind="torsional", f_sun=20.0, uncertainty=False)
    assert res.problem.periodic == "auto" and res.problem.periodic_settle == 0.5
    assert "not periodic after 0.1 s" in res.message and "settling 0.5 s" in res.message
    assert "settling 0.5 s" in res.table()
    _, _, defect = res.problem.simulated(jnp.asarray(res.theta))
    assert float(defect) <= res.problem.solver_options().periodic_tolerance
    assert abs(res.values["sun_fault"] - 0.5) < 0.02, res.values
    # the paper's gearbox: its transient dies out within the default settling time
    paper = preset("paper-sim")
    rec = simulate(build_twin(paper, kind="torsional", f_sun=60.0), duration=1.5, f_sun=60.0,
                   daq=DAQ(sample_rate=5000.0)).to_record()
    problem, _ = make_problem(rec, paper, ["sun_fault"], kind="torsional", f_sun=60.0)
    assert problem.periodic == "auto" and problem.periodic_settle == 0.1
    _, _, defect = problem.simulated(jnp.zeros(1))
    assert 0.0 < float(defect) <= problem.solver_options().periodic_tolerance
    # a run-up is integrated in full: nothing to check
    problem = dataclasses.replace(problem, observations=(
        dataclasses.replace(problem.observations[0], speed=np.array([50.0, 60.0]), ramp=True),))
    assert float(problem.simulated(jnp.zeros(1))[2]) == 0.0


@pytest.mark.slow
def test_a_batch_settles_its_tiled_response_before_solving():
    """`fit_batch` reads the same periodicity defect from its compiled solve of every record and
    fits the batch again, settling longer, where the largest is too large."""
    from _gearboxes import SLOW_SETTLING

    from dtwin.identify.fit import fit_batch
    from dtwin.spec import load_spec
    from dtwin.spec.build import daq_from_spec

    slow = load_spec(SLOW_SETTLING)
    recs = []
    for i, severity in enumerate((0.3, 0.5)):
        twin = build_twin(slow, kind="torsional", f_sun=20.0,
                          faults=(MissingTooth(severity, location="sun"),))
        recs.append(simulate(twin, duration=1.5, f_sun=20.0, discard=0.3, seed=i,
                             daq=daq_from_spec(slow, snr_db=30.0)).to_record())
    out = fit_batch(recs, slow, ["sun_fault"], kind="torsional", f_sun=20.0, uncertainty=False)
    for res, truth in zip(out, (0.3, 0.5), strict=True):
        assert res.problem.periodic_settle == 0.5 and "settling 0.5 s" in res.message
        assert abs(res.values["sun_fault"] - truth) < 0.02, (res.values, truth)
