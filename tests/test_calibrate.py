"""Calibration on records the twin did not make (../shared/independent/, an independent
simulator of the paper's simulation gearbox), and the pieces it is built from, each against a
closed form."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from dtwin.model.parts.transfer_path import window_cosine_coefficients
from dtwin.simulation.sensor_response import apply_frf, frf_gain, knot_basis
from dtwin.spec import load_spec, preset, spec_to_dict
from dtwin.spec.writer import spec_to_toml

IND = Path(__file__).resolve().parents[2] / "shared" / "independent"
needs_independent = pytest.mark.skipif(not (IND / "baseline-1.csv").exists(),
                                       reason="../shared/independent/ is not beside the checkout")


def test_window_series_of_the_exponent_window():
    # ((1 + cos φ)/2)^4 = (35 + 56 cos φ + 28 cos 2φ + 8 cos 3φ + cos 4φ) / 128 (binomial)
    c = window_cosine_coefficients(4.0, 7)
    np.testing.assert_allclose(c, np.array([35, 56, 28, 8, 1, 0, 0]) / 128, atol=1e-14)


def test_frf_interpolates_in_log_frequency():
    knots, gains = [10.0, 100.0, 1000.0], [0.0, -20.0, 10.0]
    # linear in log f: half-way (in log) between 10 and 100 Hz lies sqrt(10·100) ≈ 31.6 Hz
    g = np.asarray(frf_gain([5.0, 10.0, math.sqrt(1000.0), 100.0, 2000.0], knots, gains))
    np.testing.assert_allclose(20 * np.log10(g), [0.0, 0.0, -10.0, -20.0, 10.0], atol=1e-12)
    B = knot_basis([31.0, 500.0], knots)
    np.testing.assert_allclose(B.sum(axis=1), 1.0)


def test_frf_scales_a_sine_by_its_gain():
    fs, n = 1000.0, 4000
    t = np.arange(n) / fs
    x = np.sin(2 * np.pi * 50.0 * t)  # 50 Hz: an integer number of periods (circular filter)
    y = np.asarray(apply_frf(x, fs, [10.0, 100.0], [0.0, -20.0]))
    expected = 10 ** ((-20.0 * math.log10(5.0)) / 20.0)  # log10(50/10)/log10(100/10) of −20 dB
    assert np.max(np.abs(y)) == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("name", ["paper-sim", "paper-bench", "paper-like", "lin-parker"])
def test_spec_toml_round_trip(name, tmp_path):
    data = spec_to_dict(preset(name))
    data.pop("source")
    path = tmp_path / "s.toml"
    path.write_text(spec_to_toml(data))
    again = spec_to_dict(load_spec(path))
    again.pop("source")
    assert again == data


@pytest.fixture(scope="module")
def calibrated(independent_calibration):
    """The session's one calibration on baseline-1 (tests/_independent.py checks that the
    user's spec file is not modified)."""
    return independent_calibration


@needs_independent
def test_calibration_closes_the_gap_on_a_held_out_record(calibrated):
    """Calibrated on baseline-1 alone; baseline-2 (another noise realisation of the healthy
    machine) is scored with the calibrated twin simulated in full, nothing refitted."""
    from dtwin.identify.calibrate import heldout_gap

    res, path = calibrated
    user = heldout_gap(IND / "gearbox.toml", [IND / "baseline-2.csv"])
    cal = heldout_gap(path, [IND / "baseline-2.csv"])
    print(f"baseline-2 gap: spec as written {user.total:.2f} dB, calibrated {cal.total:.2f} dB;"
          f" bands {cal.bands}")
    assert res.gap_confirmed.total < 0.6 * res.gap_before.total
    # the result says the calibrated spec is worth using (held-out halves closer than before)
    assert res.improves and res.to_dict()["improves"] is True
    assert "NOT closer" not in res.table()
    assert cal.total < 0.25 * user.total
    for m in (1, 2, 3):
        assert cal.bands[f"mesh{m}"] < 4.0


@needs_independent
def test_calibration_meets_the_three_db_target(calibrated):
    """Issue 19's acceptance: after calibrating on baseline-1 alone, baseline-2 (held out)
    within 3 dB."""
    from dtwin.identify.calibrate import heldout_gap

    _, path = calibrated
    g = heldout_gap(path, [IND / "baseline-2.csv"])
    print(f"baseline-2 held-out gap {g.total:.2f} dB, bands {g.bands}")
    assert g.total <= 3.0


@needs_independent
def test_calibration_reports_what_the_data_do_not_determine(calibrated):
    res, _ = calibrated
    by_name = {p.name: p for p in res.parameters}
    # three equally spaced planets and Zr ≡ 0 (mod 3): only window harmonics that are
    # multiples of N = 3 reach the sensor's lines (McFadden & Smith 1985); the others are not
    # determined, c_3 (the planet-pass line's level) is
    assert by_name["window_c3"].determined
    for k in (1, 2, 4, 5):
        assert not by_name[f"window_c{k}"].determined
        assert not by_name[f"window_c{k}"].joint_with  # not even jointly with others
        assert f"window_c{k}" in res.not_determined
    # the response at the mesh harmonics is measured by strong lines
    assert any(p.determined for p in res.parameters if p.name.startswith("frf_db"))
    assert 29.5 < res.f_sun < 30.5  # 1800 rpm
    table = res.table()
    assert "not determined" in table
    # equally loaded planets: no carrier order but 3 f_c multiples, so no load shares fitted
    assert not any(p.name.startswith("load_share") for p in res.parameters)
    assert res.spec_data["imperfections"]["load_sharing"] is None


@needs_independent
def test_calibrated_spec_is_a_spec_every_command_takes(calibrated):
    from dtwin.model.parts.mesh_excitation import MeshExcitation
    from dtwin.spec.build import build_twin, daq_from_spec

    _, path = calibrated
    spec = load_spec(path)
    tw = build_twin(spec)
    assert any(isinstance(p, MeshExcitation) for p in tw.parts)
    daq = daq_from_spec(spec)
    assert daq.frf_hz is not None and len(daq.frf_hz) == len(daq.frf_db)
    assert spec["calibration"]["records"] == "baseline-1.csv"


def test_gap_counts_no_noise_bin_at_its_stated_rate():
    """The gap's default threshold is family-wise: white noise alone puts a bin of the band
    into its set in about ALPHA = 1 % of records (binomial: more than 8 of 200 has probability
    ~2e-4 if the rate is 1 %)."""
    from dtwin.identify.gap import ALPHA, gap, segment_spectra

    rng = np.random.default_rng(7)
    fs = 5000.0
    hits = 0
    for _ in range(200):
        f, Z = segment_spectra(rng.standard_normal(20000), fs, 2)
        A = np.abs(Z)
        hits += gap(f, A, np.zeros_like(A), {"all": ((0.0, 0.45 * fs),)}).counts["all"] > 0
    assert ALPHA == 0.01
    assert hits <= 8


def _toy_fit_data(seed: int = 0):
    """A calibration fit of known form: 3 parameters, 2 response knots, 1 row of 400 bins."""
    import jax.numpy as jnp

    from dtwin.identify.calibration_model import _Data
    from dtwin.simulation.sensor_response import knot_basis

    rng = np.random.default_rng(seed)
    n, p = 400, 3
    freqs = np.linspace(10.0, 2000.0, n)
    Z0 = rng.normal(size=(1, n)) + 1j * rng.normal(size=(1, n))
    JZ = 0.3 * (rng.normal(size=(1, n, p)) + 1j * rng.normal(size=(1, n, p)))
    # a fourth direction the data barely see: a column 1e-4 of the others
    JZ[..., 2] *= 1e-4
    B = knot_basis(freqs, [50.0, 1000.0])
    theta_true = np.array([0.5, -0.3, 0.0])
    A = 10.0 ** ((B @ np.array([-20.0, -30.0])) / 20.0) * np.abs(Z0[0] + JZ[0] @ theta_true)
    A = A[None, :] * np.exp(0.02 * rng.normal(size=(1, n)))
    F = np.full((1, n), 1e-4)
    return _Data(Z0=jnp.asarray(Z0), JZ=jnp.asarray(JZ), theta_lin=jnp.zeros(p),
                 A=jnp.asarray(A), F=jnp.asarray(F), S=jnp.ones((1, n)), W=jnp.ones((1, n)), B=jnp.asarray(B),
                 prior_sd=jnp.full(p, 1e3), smooth=1.0, frf_prior=60.0)


def test_calibration_fit_stops_when_its_loss_stalls_and_says_when_it_did_not():
    """The calibration's fits stop when an accepted step no longer lowers the loss
    (`StallStopping`), at the loss that plain Levenberg–Marquardt reaches with ten times the
    steps; a fit cut at its step limit says so."""
    import jax.numpy as jnp
    import optimistix as optx

    from dtwin.identify.calibration_model import _fit, _residuals

    data = _toy_fit_data()
    theta0 = jnp.zeros(3)
    theta, steps, converged, final = _fit(data, theta0, 400, 1e-8, 50, 1e-5)
    assert converged and steps < 400
    loss = float(jnp.sum(_residuals(jnp.asarray(theta), data) ** 2))
    assert abs(final - 0.5 * loss) <= 1e-9 * loss, (final, loss)  # the loss it reports is ½‖r‖²
    plain = optx.least_squares(_residuals, optx.LevenbergMarquardt(rtol=1e-12, atol=1e-14),
                               theta0, args=data, max_steps=10 * steps, throw=False)
    loss_plain = float(jnp.sum(_residuals(plain.value, data) ** 2))
    assert loss <= loss_plain * (1 + 1e-6), (loss, loss_plain)
    assert abs(theta[0] - 0.5) < 0.05 and abs(theta[1] + 0.3) < 0.05
    _, steps, converged, _ = _fit(data, theta0, 2, 1e-8, 50, 1e-5)
    assert steps == 2 and not converged


def test_joint_determination_is_read_from_the_posterior():
    """A pair the data fix only as a sum (one sensor seeing a product, in log terms) is
    determined jointly, each with the other at correlation −1; a parameter the data fix alone
    is determined; one they do not see is not determined. Closed form: the information
    ``J^T J / s2 + I / prior^2``."""
    import numpy as np

    from dtwin.identify.calibrate import CalibratedParameter
    from dtwin.identify.calibration_result import _joint

    prior = np.ones(4)
    J = np.array([[1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]) * 100.0
    info = J.T @ J + np.diag(1.0 / prior**2)
    cov = np.linalg.inv(info)
    names = ["a", "b", "c", "d"]
    joint = _joint(cov, info, prior, names, n_max=1)
    sd = np.sqrt(np.diag(cov))
    assert sd[0] > 0.5 and sd[2] < 0.5 and sd[3] == 1.0  # a, b alone: no; c: yes; d: unseen
    assert joint[0] == (("b", -1.0),) and joint[1] == (("a", -1.0),)
    assert joint[2] == () and joint[3] == ()
    p = CalibratedParameter("a", 0.0, "1", float(sd[0]), 1.0, False, joint_with=joint[0])
    assert p.status == "determined jointly with b (correlation -1.00)"
    assert p.to_dict()["status"] == p.status
    assert CalibratedParameter("d", 0.0, "1", 1.0, 1.0, False).status == "not determined"


@needs_independent
def test_calibration_reports_how_its_fit_stopped(calibrated):
    import dataclasses

    res, _ = calibrated
    assert res.fit_converged and 0 < res.fit_steps < 400
    # the fits reach their minimum: a single Levenberg–Marquardt run from θ = 0 crawled on a
    # shallow slope and left the cross-validated gap at 4.70 dB; restarted runs reach 2.48 dB
    assert res.gap_heldout.total <= 3.0 and res.gap_confirmed.total <= 3.0, res.table()
    assert f"final fit: converged in {res.fit_steps} " in res.table()
    assert res.to_dict()["fit_converged"] is True
    cut = dataclasses.replace(res, fit_steps=400, fit_converged=False)
    assert "stopped at the step limit (400 " in cut.table()


@pytest.fixture(scope="module")
def slow_settling_record(tmp_path_factory):
    """A healthy 4 s, 8 kHz record of the four-planet gearbox of `tests/_gearboxes.py`, made by
    the translational twin (the calibration fits the torsional one)."""
    from _gearboxes import SLOW_SETTLING

    from dtwin.simulation.simulate import simulate
    from dtwin.spec.build import build_twin, daq_from_spec

    spec = load_spec(SLOW_SETTLING)
    twin = build_twin(spec, kind="translational", f_sun=20.0)
    # recorded once the start-up transient has died out, as a bench records
    return spec, simulate(twin, duration=4.0, f_sun=20.0, discard=1.0,
                          daq=daq_from_spec(spec, snr_db=25.0), seed=1).to_record()


@pytest.mark.slow
def test_calibration_linearises_again_where_the_full_twin_departs(slow_settling_record,
                                                                   monkeypatch):
    """The response is first order in the excitation: where the fitted values lie beyond it,
    the twin simulated in full departs from the fit's linearised response. The confirmation
    finds that and the fit, linearised again at its values, closes most of it (measured: the
    torsional twin on the translational record, confirmed 4.8 dB against the linearised
    0.3 dB after one linearisation; 0.9 dB after the second)."""
    from dtwin.identify.calibrate import CalibrationSettings, calibrate

    spec, rec = slow_settling_record
    once = calibrate([rec], spec, kind="torsional",
                     settings=CalibrationSettings(relinearize=0))
    again = calibrate([rec], spec, kind="torsional")
    assert once.departs and once.linearisations == 1, once.departure_db
    assert again.linearisations > 1 and not again.departs, again.departure_db
    assert again.gap_confirmed.total < 0.5 * once.gap_confirmed.total, (
        once.gap_confirmed.total, again.gap_confirmed.total)
    assert again.gap_confirmed.total < 0.5 * again.gap_before.total
    # the settled response: tiling the transient instead (as the calibration did before it
    # checked the periodicity) misleads the first fit further
    import dtwin.identify.calibrate as cal
    import dtwin.identify.calibration_model as cal_model

    real = cal.simulate

    def unsettled(*args, check=True, **kw):
        res = real(*args, check=check, **kw)
        # the linearisation (check=False) sees no periodicity defect, so it keeps the tiles
        return res if check else dataclasses.replace(res, periodic_defect=None)

    monkeypatch.setattr(cal, "simulate", unsettled)  # the confirmations
    monkeypatch.setattr(cal_model, "simulate", unsettled)  # the linearisation
    tiled = calibrate([rec], spec, kind="torsional", settings=CalibrationSettings(relinearize=0))
    assert tiled.gap_confirmed.total > once.gap_confirmed.total + 3.0, (
        tiled.gap_confirmed.total, once.gap_confirmed.total)


def test_response_tangents_in_batches_are_the_jacobian(monkeypatch):
    """The response's Jacobian formed a few tangents at a time (memory, `_TANGENT_BUDGET`)
    equals the one formed all at once to rounding, and its columns equal central finite
    differences of the simulated signal: the window's c_3 (the first harmonic of the carrier
    that three equally spaced planets pass on; it acts linearly after the solve) and the first
    mesh harmonic's transmission errors (through the solve; ±100 nm, far above the solver's
    noise and within the linear range of the engaged contact). The least mesh deflections
    (calibration's contact rows) are linearised alike: batched as at once, and their columns
    for the transmission errors equal central differences."""
    import dtwin.identify.calibration_model as cal
    from dtwin.spec.build import daq_from_spec

    spec = preset("paper-sim")
    settings = cal.CalibrationSettings()
    twin, i_path, i_exc, layout = cal._prepare_twin(spec, 30.0, "torsional", settings, 2)
    daq = daq_from_spec(spec, snr_db=None, quantity="acceleration", frf_hz=None, frf_db=None)
    n = 1500  # 0.3 s at 5 kHz
    theta = np.zeros(layout.size)
    args = (twin, layout, i_path, i_exc, daq, n, 30.0, settings)
    idx = np.arange(0, 600, 3)  # the least mesh deflections' samples (calibration's contact rows)
    y_all, J_all, c_all = cal._response(*args, theta, idx)
    monkeypatch.setattr(cal, "_TANGENT_BUDGET", 3 * cal._TANGENT_BYTES_PER_SAMPLE * n * daq.oversample)
    assert cal._tangent_batch(n * daq.oversample) == 3 < layout.size
    y_b, J_b, c_b = cal._response(*args, theta, idx)
    np.testing.assert_array_equal(y_b, y_all)
    np.testing.assert_allclose(J_b, J_all, rtol=0, atol=1e-12 * np.abs(J_all).max())
    np.testing.assert_allclose(c_b.J, c_all.J, rtol=0, atol=1e-12 * np.abs(c_all.J).max())
    assert c_all.d0.shape == (2 * idx.size,) and 0 < c_all.d0.min() < c_all.mean
    h_te = 100e-9 / cal._TE_UNIT
    for j, h, tol in ((2, 1.0, 1e-4), (layout.n_window, h_te, 3e-3),
                      (layout.n_window + layout.n_harm, h_te, 3e-3)):
        ys, ds = [], []
        for s in (h, -h):
            th = theta.copy()
            th[j] = s
            y, _, c = cal._response(*args, th, idx)
            ys.append(y)
            ds.append(c.d0)
        fd = (ys[0] - ys[1]) / (2.0 * h)
        err = np.sqrt(np.mean((fd - J_all[:, j]) ** 2) / np.mean(J_all[:, j] ** 2))
        assert err < tol, (j, err)
        if j >= layout.n_window:  # the transmission error moves the least deflections
            fd = (ds[0] - ds[1]) / (2.0 * h)
            err = np.sqrt(np.mean((fd - c_all.J[:, j]) ** 2) / np.mean(c_all.J[:, j] ** 2))
            assert err < 3e-2, (j, err)


@needs_independent
def test_calibration_simulates_at_the_records_rate_not_the_specs():
    """A spec written for other records (`sensor.sample_rate` 25.6 kHz) calibrated on a 5 kHz
    record: the twin is simulated at the record's rate, so the calibration and the held-out
    gap are those of the spec with the right rate, value for value, and the calibrated spec
    carries the records' rate (it used to simulate the record's number of samples at the
    spec's rate and read them at the record's: every line in the wrong place, and for a record
    faster than its spec an internal error at the confirmation)."""
    from dtwin import read_record
    from dtwin.identify.calibrate import calibrate, heldout_gap

    rec = read_record(IND / "baseline-1.csv")
    rec = dataclasses.replace(rec, data=rec.data[:, :10_000], metadata={})  # 2 s
    right = load_spec(IND / "gearbox.toml")
    data = spec_to_dict(right)
    data.pop("source")
    data["sensor"]["sample_rate"] = 25_600.0
    wrong = load_spec(data)
    a, b = calibrate([rec], right), calibrate([rec], wrong)
    assert b.spec_data["sensor"]["sample_rate"] == a.spec_data["sensor"]["sample_rate"] == 5000.0
    for name in ("gap_before", "gap_heldout", "gap_confirmed"):
        assert getattr(b, name).total == getattr(a, name).total, name
    assert [p.value for p in b.parameters] == [p.value for p in a.parameters]
    assert a.gap_before.total < 10.0  # the same gearbox: a few dB, not the 30+ of a wrong rate
    assert heldout_gap(wrong, [rec]).total == heldout_gap(right, [rec]).total


def test_a_spec_that_already_describes_its_records_is_kept():
    """Records made by the spec's own twin (torsional, 2 s at 5 kHz, 30 dB): no calibrated
    value can generalise better than the spec as written, and the cross-validation says so —
    the calibrated spec then keeps the spec's values (no excitation, its own window and
    damping) with only the response level fitted, and its confirmed gap is the spec's (the
    calibrated values had moved along directions the records do not determine: on a
    21/31/84 gearbox they tripled the error of a later severity)."""
    from dtwin.identify.calibrate import calibrate
    from dtwin.simulation.simulate import simulate
    from dtwin.spec.build import build_twin, daq_from_spec

    data = spec_to_dict(preset("paper-sim"))
    data.pop("source")
    data["sensor"]["quantity"] = "acceleration"
    spec = load_spec(data)
    tw = build_twin(spec, kind="torsional")
    rec = simulate(tw, duration=2.0, f_sun=30.0, discard=0.1,
                   daq=daq_from_spec(spec, snr_db=30.0), seed=3).to_record()
    res = calibrate([rec], spec, kind="torsional")
    assert not res.improves and res.kept_spec, (res.gap_before.total, res.gap_heldout.total)
    out = res.spec_data
    assert "kept_spec" in out["calibration"]
    assert len(set(out["sensor"]["frf_db"])) == 1  # one flat level
    for key in ("mesh", "damping", "gears", "imperfections"):
        assert out[key] == data[key], key
    assert out["sensor"]["window_harmonics"] == data["sensor"]["window_harmonics"]
    assert res.gap_confirmed.total <= res.gap_before.total + 0.5
    assert "the spec's values kept" in res.table()
    res.spec()  # a valid spec every command takes


def test_a_calibration_the_full_twin_does_not_bear_out_is_not_adopted(monkeypatch):
    """Cross-validation scores the linearised response; the twin simulated in full must bear it
    out (dtwin.identify.calibrate.adoption). Records of the paper's gearbox with a 1 µm
    transmission error the spec as written lacks (torsional, 2 s at 5 kHz, 30 dB): the
    calibration closes the gap (measured: held-out 5.19 → 0.81 dB, confirmed 0.82 dB). Here the
    confirmation is made 9.5 dB louder than the twin it simulates, a twin that does not do
    what its linearised fit says, at a departure the relinearisation rule alone lets pass:
    the fit is linearised again because the full twin is no closer than the spec as written,
    and when it never is, the spec's values are kept and the result says why. (Found on a
    four-planet record where the first confirmation, 1.23 dB, stood above the spec's 1.07 dB
    at a departure of 0.83 dB and was adopted; linearised again, it confirms at 0.40 dB;
    docs/calibration.md.)"""
    import dtwin.identify.calibrate as cal
    from dtwin.simulation.simulate import simulate
    from dtwin.spec.build import build_twin, daq_from_spec

    data = spec_to_dict(preset("paper-sim"))
    data.pop("source")
    data["sensor"]["quantity"] = "acceleration"
    spec = load_spec(data)
    truth = dict(data, mesh=dict(data["mesh"], te_amplitude=1e-6))
    rec = simulate(build_twin(load_spec(truth), kind="torsional"), duration=2.0, f_sun=30.0,
                   discard=0.1, daq=daq_from_spec(spec, snr_db=30.0), seed=3).to_record()
    real = cal.simulate

    def louder(*args, check=True, **kw):  # the confirmations (the linearisation: check=False)
        res = real(*args, check=check, **kw)
        return dataclasses.replace(res, signal=res.signal * 3.0) if check else res

    monkeypatch.setattr(cal, "simulate", louder)
    said = []
    res = cal.calibrate([rec], spec, kind="torsional", progress=said.append,
                        settings=cal.CalibrationSettings(relinearize=1, relinearize_db=50.0,
                                                         converge_db=50.0))
    assert res.gap_heldout.total < 0.5 * res.gap_before.total  # cross-validation alone adopts
    assert any("no closer to the records than the spec as written" in m for m in said), said
    assert not res.departs and res.heldout_full_db is None
    assert res.calibrated_confirmed_db >= res.gap_before.total
    assert not res.improves and res.kept_spec
    assert "once simulated in full" in res.rejection and "NOT adopted" in res.table()
    assert "once simulated in full" in res.spec_data["calibration"]["kept_spec"]
    assert res.spec_data["mesh"] == data["mesh"]  # the spec's own values
    assert res.to_dict()["rejection"] == res.rejection


def test_adoption_rules():
    """dtwin.identify.calibrate.adoption, rule by rule: held out, simulated in full, and the
    twin's own cross-validation where it departs from the linearised response."""
    from dtwin.identify.calibrate import adoption

    assert adoption(4.3, 0.7, 2.7) == "" and adoption(4.3, 0.7, 2.7, 2.96) == ""
    assert "held-out halves" in adoption(1.0, 1.2, 0.5)
    assert "once simulated in full, 4.50 against 4.30 dB" in adoption(4.3, 0.7, 4.5)
    assert "simulated in full, no closer to the held-out halves" in adoption(4.3, 0.7, 2.7, 4.4)


def test_calibration_fits_no_more_mesh_harmonics_than_have_a_registry_name():
    """Every calibrated quantity has a registry name: the excitation is fitted for every mesh
    harmonic below 0.45 × the rate up to N_EXCITATION_HARMONICS (a 5 kHz record of the paper's
    gearbox: 4; a 25.6 kHz one: 12, not 23), and a setting beyond it is refused."""
    from dtwin.errors import SpecError
    from dtwin.identify.calibrate import CalibrationSettings, mesh_harmonics
    from dtwin.model.registry import N_EXCITATION_HARMONICS, REGISTRY

    f_mesh = 21 * 30.0 * 81 / 102  # the independent gearbox at 1800 rpm: 500.3 Hz
    auto = CalibrationSettings()
    assert mesh_harmonics(auto, 5000.0, f_mesh) == 4
    assert mesh_harmonics(auto, 25600.0, f_mesh) == N_EXCITATION_HARMONICS == 12
    assert mesh_harmonics(CalibrationSettings(mesh_harmonics=6), 25600.0, f_mesh) == 6
    assert f"excitation_ring_sin_{N_EXCITATION_HARMONICS}" in REGISTRY
    for bad in (0, N_EXCITATION_HARMONICS + 1):
        with pytest.raises(SpecError, match="mesh_harmonics"):
            CalibrationSettings(mesh_harmonics=bad)
    with pytest.raises(SpecError, match="window_terms"):
        CalibrationSettings(window_terms=14)


@pytest.mark.parametrize("n_planets", [3, 4])
def test_calibrations_window_reaches_the_second_planet_pass(n_planets):
    """A fixed sensor sees the window of N equal, equally spaced planets only at its harmonics
    k N (closed form: ``sum_n cos(k (theta + 2 pi n / N)) = N cos(k theta)`` when N divides k,
    else 0), so the planet-pass lines ``N f_c`` and ``2 N f_c`` need the window terms ``c_N``
    and ``c_{2N}``. Seven terms, the count once fixed, stop at ``c_6``: a four-planet gear set's
    ``8 f_c`` line went unmodelled (its held-out low band 10 dB). The default count follows the
    spec: ``2 N + 1``."""
    from dtwin.identify.calibrate import CalibrationSettings
    from dtwin.identify.calibration_model import _prepare_twin
    from dtwin.identify.calibration_settings import window_terms_for
    from dtwin.model.registry import N_WINDOW_TERMS

    assert window_terms_for(n_planets) == 2 * n_planets + 1
    assert window_terms_for(40) == N_WINDOW_TERMS
    d = spec_to_dict(preset("paper-sim"))
    d["gears"].update(z_sun=20, z_planet=30, z_ring=80, n_planets=n_planets)
    spec = load_spec(d)
    twin, i_path, _, layout = _prepare_twin(spec, 30.0, "torsional", CalibrationSettings(), 4)
    assert layout.n_window == 2 * n_planets  # c_1 … c_{2N} free
    # the twin's own window of equal static forces over one carrier turn: its harmonics
    path = twin.parts[i_path]
    c = np.ones(len(path.window_harmonics))
    theta = np.linspace(0.0, 2 * np.pi, 256, endpoint=False)
    phi = theta[:, None] + np.asarray(twin.lp.planet_angles)[None, :] - float(path.sensor_angle)
    seen = np.abs(np.fft.rfft((np.cos(phi[..., None] * np.arange(c.size)) @ c).sum(axis=1)))
    orders = [k for k in range(1, c.size + 3) if seen[k] > 1e-9 * seen[0]]
    assert orders == [n_planets, 2 * n_planets]
